//! `tending plot pareto`: parts delivered against contacts per robot-step, one panel per
//! setup, one point per method (a `tending eval` results.csv each, mean over its seeds).
//! Up and to the left is better; the points a method can be compared on are in one panel.

use crate::chart;
use anyhow::{anyhow, Result};
use clap::Args;
use plotters::prelude::*;
use records::EvalResultRecord;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct ParetoArgs {
    /// `tending eval` results.csv files, one per method (its `policy` column names it).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value = "parts vs contacts")]
    pub title: String,
    /// Fit the parts axis to the points instead of starting it at 0, and join the points
    /// of one method at different safety margins (names ending in "N mm" or "N/M mm",
    /// `tending eval --margins` files) with a line: a sweep's
    /// front (bench/safety/margin_sweep.sh).
    #[arg(long)]
    pub sweep: bool,
}

/// setup -> method -> (mean parts, mean contacts per robot-step) over the method's rows.
pub(crate) type Points = BTreeMap<String, BTreeMap<String, (f64, f64)>>;

/// Methods in first-read order (shown names, [`short_names`]) and every setup's points.
/// A method's rows may be spread over several files; non-finite numbers are refused
/// with the file, line and column.
pub(crate) fn read(files: &[PathBuf]) -> Result<(Vec<String>, Points)> {
    let mut methods: Vec<String> = vec![];
    // (setup, method) -> sums of parts and contacts, and rows: a method's rows may be spread
    // over several files (one per group of setups, as in docs/safety).
    let mut sums: BTreeMap<(String, String), (f64, f64, f64)> = BTreeMap::new();
    for f in files {
        for records::Line { line, record: row } in records::read::<EvalResultRecord>(f)? {
            let contacts = row.contacts_per_robot_step.ok_or_else(|| {
                anyhow!(
                    "{}:{line}: no contacts_per_robot_step (a results.csv written before \
                     the contact rates; rerun `tending eval`)",
                    f.display()
                )
            })?;
            let parts = records::finite(f, line, "parts_delivered", row.parts_delivered)?;
            let contacts = records::finite(f, line, "contacts_per_robot_step", contacts)?;
            let m = row.policy;
            if !methods.contains(&m) {
                methods.push(m.clone());
            }
            let e = sums.entry((row.setup, m)).or_default();
            *e = (e.0 + parts, e.1 + contacts, e.2 + 1.0);
        }
    }
    let labels = short_names(&methods);
    let label = |m: &str| labels[methods.iter().position(|x| x == m).unwrap_or(0)].clone();
    let mut pts: Points = BTreeMap::new();
    for ((setup, m), (p, c, n)) in sums {
        pts.entry(setup)
            .or_default()
            .insert(label(&m), (p / n, c / n));
    }
    Ok((labels, pts))
}

/// The names to show for methods (the `policy` column of results.csv): without the
/// checkpoint file in parentheses, unless two methods differ only in it (the bundled
/// policy and the always-"matched" checkpoint that stood for matching-ORCA before
/// `--policy matching-orca` are both `smappo targets+orca`).
pub(crate) fn short_names(methods: &[String]) -> Vec<String> {
    let short = |m: &str| m.split(" (").next().unwrap_or(m).to_string();
    methods
        .iter()
        .map(|m| {
            let s = short(m);
            let clash = methods.iter().any(|o| o != m && short(o) == s);
            if clash {
                m.clone()
            } else {
                s
            }
        })
        .collect()
}

const COLOURS: [RGBColor; 12] = chart::PALETTE;

/// Legend entries per row of the figure's one legend, and the height of a row.
const LEGEND_COLS: usize = 3;
const LEGEND_ROW: u32 = 24;

pub(crate) fn setup_key(s: &str) -> Vec<u64> {
    s.split(['.', '_']).filter_map(|x| x.parse().ok()).collect()
}

pub fn run(a: &ParetoArgs) -> Result<()> {
    let (methods, pts) = read(&a.files)?;
    let mut setups: Vec<&String> = pts.keys().collect();
    setups.sort_by_key(|s| setup_key(s));
    draw(&a.out, &a.title, &methods, &setups, &pts, a.sweep)
}

/// A method's name without its safety margin ("greedy-orca 30 mm" -> "greedy-orca"):
/// the points of one sweep share it.
fn family(method: &str) -> &str {
    match method.rsplit_once(' ') {
        Some((rest, "mm")) => rest.rsplit_once(' ').map_or(rest, |(f, _)| f),
        _ => method,
    }
}

fn draw(
    path: &Path,
    title: &str,
    methods: &[String],
    setups: &[&String],
    pts: &Points,
    sweep: bool,
) -> Result<()> {
    chart::init();
    let e = |x: DrawingAreaErrorKind<_>| anyhow::anyhow!("plot {}: {x:?}", path.display());
    let cols = setups.len().clamp(1, 3);
    let rows = setups.len().div_ceil(cols).max(1);
    let (pw, ph) = (420u32, 330u32);
    let legend_h = 16 + LEGEND_ROW * methods.len().div_ceil(LEGEND_COLS).max(1) as u32;
    let root = BitMapBackend::new(path, (pw * cols as u32, 50 + ph * rows as u32 + legend_h))
        .into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(title, (chart::FONT, chart::TITLE)).map_err(e)?;
    // One legend for the figure, below the panels: a legend inside each panel covered
    // the points once there were more than a few methods.
    let (grid, legend_area) = root.split_vertically(ph * rows as u32);
    legend(&legend_area, methods, pw * cols as u32).map_err(e)?;
    let panels = grid.split_evenly((rows, cols));
    for (setup, area) in setups.iter().zip(panels.iter()) {
        panel(area, setup, methods, &pts[*setup], sweep).map_err(e)?;
    }
    root.present().map_err(e)?;
    Ok(())
}

/// The figure's legend: a coloured dot and the method's name, `LEGEND_COLS` per row.
fn legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    methods: &[String],
    width: u32,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let col_w = (width / LEGEND_COLS as u32) as i32;
    for (i, m) in methods.iter().enumerate() {
        let (x, y) = (
            20 + col_w * (i % LEGEND_COLS) as i32,
            8 + (LEGEND_ROW * (i / LEGEND_COLS) as u32) as i32,
        );
        let col = COLOURS[i % COLOURS.len()];
        area.draw(&Circle::new((x, y + 8), 6, col.filled()))?;
        area.draw(&Text::new(
            m.as_str(),
            (x + 14, y),
            (chart::FONT, chart::LABEL).into_font().color(&chart::INK),
        ))?;
    }
    Ok(())
}

/// One setup: a point per method (labelled with its parts, coloured as in the legend).
fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    setup: &str,
    methods: &[String],
    by: &BTreeMap<String, (f64, f64)>,
    sweep: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let xmax = by.values().map(|p| p.1).fold(0.0, f64::max).max(1e-3) * 1.15;
    let hi = by.values().map(|p| p.0).fold(0.0, f64::max).max(1.0);
    // A sweep's points differ by a few parts: fit the axis to them, 15 % of the span
    // (at least one part) either side; otherwise from 0 to 15 % above the highest.
    let (ymin, ymax) = if sweep {
        let lo = by.values().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let ymin = (lo - 0.15 * (hi - lo).max(1.0)).max(0.0);
        (ymin, hi + 0.15 * (hi - ymin).max(1.0))
    } else {
        (0.0, hi * 1.15)
    };
    let mut c = ChartBuilder::on(area)
        .caption(setup, (chart::FONT, chart::CAPTION))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..xmax, ymin..ymax)?;
    chart::mesh(&mut c, "contacts per robot-step", "parts delivered")?;
    if sweep {
        // One line per family through its points in order of contacts, in the colour of
        // its first method.
        let mut done: Vec<&str> = vec![];
        for (i, m) in methods.iter().enumerate() {
            let f = family(m);
            if done.contains(&f) {
                continue;
            }
            done.push(f);
            let mut line: Vec<(f64, f64)> = methods
                .iter()
                .filter(|x| family(x) == f)
                .filter_map(|x| by.get(x).map(|&(p, c)| (c, p)))
                .collect();
            line.sort_by(|a, b| a.0.total_cmp(&b.0));
            let col = COLOURS[i % COLOURS.len()];
            c.draw_series(LineSeries::new(line, col.stroke_width(2)))?;
        }
    }
    for (i, m) in methods.iter().enumerate() {
        let Some(&(parts, contacts)) = by.get(m) else {
            continue;
        };
        let col = COLOURS[i % COLOURS.len()];
        c.draw_series(std::iter::once(
            EmptyElement::at((contacts, parts))
                + Circle::new((0, 0), 6, col.filled())
                + Text::new(
                    format!("{parts:.0}"),
                    (9, -7),
                    (chart::FONT, chart::TICK).into_font().color(&col),
                ),
        ))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_eval_csvs_and_draws_a_png() {
        let dir = std::env::temp_dir().join(format!("pareto_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let a = dir.join("a.csv");
        let b = dir.join("b.csv");
        let row = |policy: &str, seed, parts, contacts| EvalResultRecord {
            policy: policy.into(),
            setup: "6.4_2".into(),
            seed,
            parts_delivered: parts,
            contacts_per_robot_step: Some(contacts),
            ..Default::default()
        };
        let write = |p: &PathBuf, rows: &[EvalResultRecord]| {
            std::fs::write(p, records::to_text(rows).unwrap()).unwrap()
        };
        write(
            &a,
            &[row("greedy", 0, 20.0, 0.01), row("greedy", 1, 30.0, 0.03)],
        );
        write(&b, &[row("smappo (x.safetensors)", 0, 35.0, 0.25)]);
        let (methods, pts) = read(&[a.clone(), b.clone()]).unwrap();
        assert_eq!(methods, ["greedy", "smappo"]);
        assert_eq!(pts["6.4_2"]["greedy"], (25.0, 0.02));
        // A method's rows in a second file are the same method, averaged with the first's.
        let a2 = dir.join("a2.csv");
        write(&a2, &[row("greedy", 2, 40.0, 0.05)]);
        let (methods, pts) = read(&[a.clone(), b.clone(), a2]).unwrap();
        assert_eq!(methods, ["greedy", "smappo"]);
        assert_eq!(pts["6.4_2"]["greedy"].0, 30.0);
        // Two checkpoints of one kind keep their file names apart.
        let names = short_names(&[
            "smappo targets+orca (a.safetensors)".into(),
            "smappo targets+orca (b.safetensors)".into(),
            "smappo+orca (a.safetensors)".into(),
            "greedy".into(),
        ]);
        assert_eq!(
            names,
            [
                "smappo targets+orca (a.safetensors)",
                "smappo targets+orca (b.safetensors)",
                "smappo+orca",
                "greedy"
            ]
        );
        let out = dir.join("p.png");
        run(&ParetoArgs {
            files: vec![a, b],
            out: out.clone(),
            title: "t".into(),
            sweep: false,
        })
        .unwrap();
        assert!(std::fs::metadata(&out).unwrap().len() > 1000);
        // A sweep joins the points of one method at several margins.
        run(&ParetoArgs {
            files: vec![dir.join("a.csv"), dir.join("b.csv")],
            out: out.clone(),
            title: "t".into(),
            sweep: true,
        })
        .unwrap();
        assert_eq!(family("greedy-orca 30 mm"), "greedy-orca");
        assert_eq!(
            family("smappo targets+orca 25/40 mm"),
            "smappo targets+orca"
        );
        assert_eq!(family("greedy-orca"), "greedy-orca");
        assert_eq!(family("smappo+orca"), "smappo+orca");
        // A results.csv of before the contact rates is refused with its name.
        let old = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results/greedy_6.4_2.csv");
        let err = format!("{:#}", read(&[old]).unwrap_err());
        assert!(
            err.contains("greedy_6.4_2.csv:2") && err.contains("contacts"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
