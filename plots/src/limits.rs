//! `tending plot limits`: every method's parts as a multiple of the best scripted
//! baseline's, one column per setup, with the target (1.1x, issue 10) and the ceiling that
//! `tending bound` puts on any controller. It shows in one chart where the target is met,
//! where it is missed, and how much room physics leaves above it: a ceiling just above
//! the target line means the target asks for nearly every part the layout allows.

use crate::chart;
use anyhow::{bail, Result};
use clap::Args;
use plotters::prelude::*;
use records::PartsBoundRecord;
use std::collections::BTreeMap;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct LimitsArgs {
    /// `tending eval` results.csv files. A method's rows may be spread over several files
    /// (one per group of setups); rows are merged by the method's name.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// `tending bound --out` files covering the setups of the results.
    #[arg(long, required = true, num_args = 1..)]
    pub bound: Vec<PathBuf>,
    /// The scripted baselines, by method name: the target is `--target` x the best of them.
    #[arg(long, value_delimiter = ',', default_value = "greedy,greedy-orca")]
    pub scripts: Vec<String>,
    /// The target, as a multiple of the best script's parts.
    #[arg(long, default_value_t = 1.1)]
    pub target: f64,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(
        long,
        default_value = "parts / best script's parts: the target and the ceiling"
    )]
    pub title: String,
}

/// Mean of a value over rows, kept as a running sum.
#[derive(Default, Clone, Copy)]
struct Mean(f64, f64);

impl Mean {
    fn add(&mut self, v: f64) {
        self.0 += v;
        self.1 += 1.0;
    }
    fn get(self) -> f64 {
        self.0 / self.1
    }
}

/// What the chart shows for one setup.
#[derive(Debug, Clone, PartialEq)]
struct Column {
    setup: String,
    /// Parts of the best script.
    best: f64,
    /// (method, parts / best), in the order the methods were first read.
    ratios: Vec<(String, f64)>,
    /// The bound / best.
    ceiling: f64,
}

/// Methods in first-read order, and the columns of every setup that has a bound and at
/// least one script.
fn columns(a: &LimitsArgs) -> Result<(Vec<String>, Vec<Column>)> {
    // Mean parts per setup and method, merged over files and named as `tending plot
    // pareto` names them (so --scripts matches what its legend shows).
    let (methods, points) = crate::pareto::read(&a.files)?;
    let mut bound: BTreeMap<String, Mean> = BTreeMap::new();
    for f in &a.bound {
        for records::Line { line, record: r } in records::read::<PartsBoundRecord>(f)? {
            let v = records::finite(f, line, "parts_bound", r.parts_bound)?;
            bound.entry(r.setup).or_default().add(v);
        }
    }
    if !a.scripts.iter().any(|s| methods.contains(s)) {
        bail!(
            "none of the scripts {:?} is among the methods read ({})",
            a.scripts,
            methods.join(", ")
        );
    }
    let mut cols = vec![];
    for (setup, by) in &points {
        let best = a
            .scripts
            .iter()
            .filter_map(|s| by.get(s).map(|p| p.0))
            .fold(f64::NAN, f64::max);
        let Some(b) = bound.get(setup) else {
            bail!(
                "setup {setup} has results but no bound (pass its `tending bound --out` file \
                 to --bound)"
            );
        };
        if best.is_nan() || best <= 0.0 {
            continue; // no script ran here: nothing to compare with
        }
        cols.push(Column {
            setup: setup.clone(),
            best,
            ratios: methods
                .iter()
                .filter_map(|m| by.get(m).map(|p| (m.clone(), p.0 / best)))
                .collect(),
            ceiling: b.get() / best,
        });
    }
    if cols.is_empty() {
        bail!("no setup has both a script's results and a bound");
    }
    cols.sort_by_key(|c| crate::pareto::setup_key(&c.setup));
    Ok((methods, cols))
}

const TARGET: RGBColor = RGBColor(200, 40, 40);

pub fn run(a: &LimitsArgs) -> Result<()> {
    let (methods, cols) = columns(a)?;
    chart::init();
    let e = |x: DrawingAreaErrorKind<_>| anyhow::anyhow!("plot {}: {x:?}", a.out.display());
    let root = BitMapBackend::new(&a.out, (200 + 46 * cols.len() as u32, 640)).into_drawing_area();
    draw(&root, &a.title, a.target, &methods, &cols).map_err(e)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    target: f64,
    methods: &[String],
    cols: &[Column],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let n = cols.len();
    root.fill(&WHITE)?;
    let root = root.titled(title, (chart::FONT, chart::TITLE))?;
    // Scripts far below the best (plain greedy) and ceilings far above (robot-poor and
    // storage-bound layouts) would squash the band where the target is decided: clip the
    // axis and mark what lies beyond it.
    let (ylo, yhi) = (0.7, 1.3);
    let mut c = ChartBuilder::on(&root)
        .margin(14)
        .x_label_area_size(80)
        .y_label_area_size(64)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), ylo..yhi)?;
    let names: Vec<String> = cols.iter().map(|c| c.setup.clone()).collect();
    c.configure_mesh()
        .light_line_style(TRANSPARENT)
        .bold_line_style(chart::GRID)
        .disable_x_mesh()
        .x_labels(n)
        .x_label_formatter(&|v| chart::category_label(&names, *v))
        .x_label_style(
            (chart::FONT, chart::TICK)
                .into_font()
                .transform(FontTransform::Rotate90),
        )
        .y_desc("parts / best script's parts (seeds' mean; hollow: below the axis)")
        .axis_desc_style((chart::FONT, chart::LABEL))
        .y_label_style((chart::FONT, chart::TICK))
        .draw()?;
    let x0 = -0.5;
    let x1 = n as f64 - 0.5;
    c.draw_series(LineSeries::new(
        [(x0, target), (x1, target)],
        TARGET.stroke_width(2),
    ))?
    .label(format!("target: {target}x the best script"))
    .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], TARGET.stroke_width(2)));
    c.draw_series(LineSeries::new([(x0, 1.0), (x1, 1.0)], chart::INK.mix(0.4)))?;
    // The ceiling: a black dash per setup, or one at the top with its value beneath.
    let dash = || PathElement::new([(-14, 0), (14, 0)], chart::INK.stroke_width(3));
    c.draw_series(
        cols.iter()
            .enumerate()
            .filter(|(_, col)| col.ceiling <= yhi)
            .map(|(i, col)| EmptyElement::at((i as f64, col.ceiling)) + dash()),
    )?
    .label("ceiling: the parts bound (value if off the chart)")
    .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], chart::INK.stroke_width(3)));
    c.draw_series(
        cols.iter()
            .enumerate()
            .filter(|(_, col)| col.ceiling > yhi)
            .map(|(i, col)| {
                EmptyElement::at((i as f64, yhi))
                    + dash()
                    + Text::new(
                        format!("{:.2}", col.ceiling),
                        (-14, 6),
                        (chart::FONT, chart::TICK - 2)
                            .into_font()
                            .color(&chart::INK),
                    )
            }),
    )?;
    // Methods side by side within a column.
    let k = methods.len().max(1) as f64;
    for (mi, m) in methods.iter().enumerate() {
        // the palette's red is the target line's
        let col = chart::PALETTE[(mi + 1) % chart::PALETTE.len()];
        let dx = (mi as f64 - (k - 1.0) / 2.0) * 0.12;
        let pts = cols.iter().enumerate().filter_map(|(i, c)| {
            let r = c.ratios.iter().find(|(x, _)| x == m)?.1;
            Some((i as f64 + dx, r))
        });
        c.draw_series(pts.map(|(x, r)| {
            // Below the axis: hollow, just inside it (clear of the setup labels).
            let style = if r < ylo {
                col.stroke_width(2)
            } else {
                col.filled()
            };
            Circle::new((x, r.clamp(ylo + 0.012, yhi)), 5, style)
        }))?
        .label(if m.is_empty() { "?" } else { m.as_str() })
        .legend(move |(x, y)| Circle::new((x + 9, y), 5, col.filled()));
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.9))
        .border_style(chart::INK)
        .label_font((chart::FONT, chart::TICK))
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use records::EvalResultRecord;

    fn row(policy: &str, setup: &str, seed: u64, parts: f64) -> EvalResultRecord {
        EvalResultRecord {
            policy: policy.into(),
            setup: setup.into(),
            seed,
            parts_delivered: parts,
            contacts_per_robot_step: Some(0.0),
            ..Default::default()
        }
    }

    fn bound(setup: &str, seed: u64, b: f64) -> PartsBoundRecord {
        PartsBoundRecord {
            setup: setup.into(),
            seed,
            parts_bound: b,
            machine_bound: b,
            robot_bound: b,
            p_max: b,
            ..Default::default()
        }
    }

    #[test]
    fn ratios_are_to_the_best_script_over_merged_files() {
        let dir = std::env::temp_dir().join(format!("limits_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let w = |name: &str, text: String| {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        // greedy-orca's rows are in two files (two groups of setups), as in docs/safety.
        let files = vec![
            w(
                "a.csv",
                records::to_text(&[
                    row("greedy", "6.4_2", 0, 20.0),
                    row("greedy", "2.2_2", 0, 8.0),
                ])
                .unwrap(),
            ),
            w(
                "b.csv",
                records::to_text(&[
                    row("greedy-orca", "6.4_2", 0, 30.0),
                    row("greedy-orca", "6.4_2", 1, 34.0),
                ])
                .unwrap(),
            ),
            w(
                "c.csv",
                records::to_text(&[row("greedy-orca", "2.2_2", 0, 10.0)]).unwrap(),
            ),
            w(
                "d.csv",
                records::to_text(&[row("smappo targets+orca (x.safetensors)", "6.4_2", 0, 35.2)])
                    .unwrap(),
            ),
        ];
        let b = w(
            "bound.csv",
            records::to_text(&[
                bound("6.4_2", 0, 40.0),
                bound("6.4_2", 1, 38.4),
                bound("2.2_2", 0, 20.0),
            ])
            .unwrap(),
        );
        let mut a = LimitsArgs {
            files,
            bound: vec![b],
            scripts: vec!["greedy".into(), "greedy-orca".into()],
            target: 1.1,
            out: dir.join("limits.png"),
            title: "t".into(),
        };
        let (methods, cols) = columns(&a).unwrap();
        assert_eq!(methods, ["greedy", "greedy-orca", "smappo targets+orca"]);
        assert_eq!(
            cols.iter().map(|c| c.setup.as_str()).collect::<Vec<_>>(),
            ["2.2_2", "6.4_2"]
        );
        let c = &cols[1];
        assert_eq!(c.best, 32.0); // greedy-orca's mean over its seeds beats greedy
        assert_eq!(c.ratios[2].0, "smappo targets+orca");
        assert!((c.ratios[2].1 - 1.1).abs() < 1e-12);
        assert_eq!(c.ratios[0].1, 20.0 / 32.0);
        assert!((c.ceiling - 39.2 / 32.0).abs() < 1e-12);
        run(&a).unwrap();
        assert!(std::fs::metadata(&a.out).unwrap().len() > 1000);

        // A setup with results but no bound, or no script among the methods, is refused
        // with what is missing.
        a.bound = vec![w(
            "b2.csv",
            records::to_text(&[bound("6.4_2", 0, 40.0)]).unwrap(),
        )];
        let err = format!("{:#}", columns(&a).unwrap_err());
        assert!(err.contains("2.2_2") && err.contains("--bound"), "{err}");
        a.scripts = vec!["matching-orca".into()];
        let err = format!("{:#}", columns(&a).unwrap_err());
        assert!(
            err.contains("matching-orca") && err.contains("greedy-orca"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
