//! The figures of `tending plot bars|curves`, through plotters' chart layer with the bundled
//! font ([`crate::chart`], docs/adr/0010-plotting.md): every PNG has a title, axis labels and
//! a legend.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use anyhow::{anyhow, bail, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::KNOWN_MODELS;
use super::{model_color, model_label, model_rank, sort_setups, BarStat, CurveGroup, Metric};
use crate::chart::{self, Xy, INK};

const SOFT: RGBColor = RGBColor(100, 100, 100);

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
type Drawn =
    Result<(), DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>>;

/// A PNG of `w` x `h` pixels at `path` (its directory created), white, with `title` on top;
/// returns the area under the title.
fn canvas<'a>(path: &'a Path, w: u32, h: u32, title: &str) -> Result<(Area<'a>, Area<'a>)> {
    chart::init();
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow!("{}: cannot create: {e}", dir.display()))?;
    }
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    let err = |e| anyhow!("plot {}: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let body = root
        .titled(title, (chart::FONT, chart::TITLE))
        .map_err(err)?;
    Ok((root, body))
}

/// A line in the legend's sample box.
fn legend_line(c: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
}

/// The nice round y range (from `lo` to `hi`, about `target` ticks) and its step.
pub(super) fn nice_range(lo: f64, hi: f64, target: usize) -> (f64, f64, f64) {
    let step = nice_step((hi - lo).max(1e-9), target);
    let lo = (lo / step).floor() * step;
    let hi = ((hi / step).ceil() * step).max(lo + step);
    (lo, hi, step)
}

fn nice_step(range: f64, target: usize) -> f64 {
    let raw = range / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let nice = if f <= 1.0 {
        1.0
    } else if f <= 2.0 {
        2.0
    } else if f <= 2.5 {
        2.5
    } else if f <= 5.0 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

// ---------------------------------------------------------------------------------------
// Bars

/// One bar chart: metric `k` of every (setup, model), error bars over training seeds,
/// the paper's values as diamonds.
pub(super) fn draw_bars(
    stats: &[BarStat],
    k: usize,
    title: &str,
    ylabel: &str,
    paper: Option<&BTreeMap<(String, String), f64>>,
    path: &Path,
) -> Result<()> {
    let mut setups: Vec<String> = stats.iter().map(|s| s.setup.clone()).collect();
    sort_setups(&mut setups);
    setups.dedup();
    let mut models: Vec<String> = stats.iter().map(|s| s.model.clone()).collect();
    models.sort_by_key(|m| model_rank(m));
    models.dedup();
    let paper_pts: Vec<(usize, usize, f64)> = paper
        .map(|p| {
            let mut v = vec![];
            for (si, s) in setups.iter().enumerate() {
                for (mi, m) in models.iter().enumerate() {
                    if let Some(x) = p.get(&(s.clone(), m.clone())) {
                        v.push((si, mi, *x));
                    }
                }
            }
            v
        })
        .unwrap_or_default();
    let hi = stats
        .iter()
        .map(|s| s.mean[k] + s.std[k])
        .chain(paper_pts.iter().map(|p| p.2))
        .fold(0.0, f64::max);
    let (_, mut yhi, _) = nice_range(0.0, hi * 1.04, 6);
    if k == 2 && yhi > 1.0 && hi <= 1.0 {
        yhi = 1.0; // MU
    }
    let nm = models.len().max(1);
    let group_w = (nm as u32 * 26 + 40).max(110);
    let w = (112 + setups.len() as u32 * group_w + 30).max(900);
    let (root, body) = canvas(path, w, 600, title)?;
    let bars = Bars {
        stats,
        k,
        setups: &setups,
        models: &models,
        paper: &paper_pts,
        yhi,
        ylabel,
    };
    bars.draw(&body)
        .and_then(|()| root.present())
        .map_err(|e| anyhow!("plot {}: {e:?}", path.display()))
}

struct Bars<'a> {
    stats: &'a [BarStat],
    k: usize,
    setups: &'a [String],
    models: &'a [String],
    paper: &'a [(usize, usize, f64)],
    yhi: f64,
    ylabel: &'a str,
}

impl Bars<'_> {
    /// Bar `mi` of group `si`: its x range (groups are centred on integers).
    fn x(&self, si: usize, mi: usize) -> (f64, f64) {
        let nm = self.models.len().max(1) as f64;
        let inner = (0.18 * nm).min(0.8);
        let bw = inner / nm;
        let x0 = si as f64 - inner / 2.0 + mi as f64 * bw;
        (x0 + 0.01, x0 + bw - 0.01)
    }

    /// The most runs of a model over setups (what the legend says).
    fn runs(&self, m: &str) -> usize {
        self.stats
            .iter()
            .filter(|s| s.model == m)
            .map(|s| s.n)
            .max()
            .unwrap_or(0)
    }

    fn draw(&self, area: &Area) -> Drawn {
        let n = self.setups.len().max(1);
        let mut c = ChartBuilder::on(area)
            .caption(
                "bar: mean over training seeds;  error bar: std over seeds",
                (chart::FONT, chart::LABEL).into_font().color(&SOFT),
            )
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(-0.5..(n as f64 - 0.5), 0.0..self.yhi)?;
        // Integer x ticks are the group centres: label them with the setup.
        let setups = self.setups;
        c.configure_mesh()
            .light_line_style(TRANSPARENT)
            .bold_line_style(chart::GRID)
            .disable_x_mesh()
            .x_labels(n)
            .x_label_formatter(&|v| chart::category_label(setups, *v))
            .x_desc("setup (robots.machines_storages)")
            .y_desc(self.ylabel)
            .axis_desc_style((chart::FONT, chart::LABEL))
            .label_style((chart::FONT, chart::TICK))
            .draw()?;
        let others: Vec<String> = self
            .models
            .iter()
            .filter(|m| !KNOWN_MODELS.contains(&m.as_str()))
            .cloned()
            .collect();
        for (mi, m) in self.models.iter().enumerate() {
            let color = model_color(m, &others);
            self.draw_model(&mut c, mi, m, color)?;
        }
        if !self.paper.is_empty() {
            let diamonds = self.paper.iter().map(|&(si, mi, v)| {
                let (a, b) = self.x(si, mi);
                EmptyElement::at(((a + b) / 2.0, v)) + diamond(7)
            });
            c.draw_series(diamonds)?
                .label("paper, full budget")
                .legend(|(x, y)| EmptyElement::at((x + 10, y)) + diamond(6));
        }
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(chart::INK)
            .label_font((chart::FONT, chart::TICK))
            .draw()
    }

    /// One model's bars, error bars and, where a setup has fewer runs than the legend
    /// says (an experiment still running), `n=` above the bar.
    fn draw_model(
        &self,
        c: &mut ChartContext<BitMapBackend, Xy>,
        mi: usize,
        m: &str,
        color: RGBColor,
    ) -> Drawn {
        let k = self.k;
        let mine: Vec<(usize, &BarStat)> = self
            .setups
            .iter()
            .enumerate()
            .filter_map(|(si, s)| {
                let st = self.stats.iter().find(|t| &t.setup == s && t.model == m)?;
                Some((si, st))
            })
            .collect();
        let runs = self.runs(m);
        c.draw_series(mine.iter().map(|&(si, st)| {
            let (a, b) = self.x(si, mi);
            Rectangle::new([(a, 0.0), (b, st.mean[k])], color.filled())
        }))?
        .label(model_label(m, runs))
        .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], color.filled()));
        for &(si, st) in &mine {
            let (a, b) = self.x(si, mi);
            let cx = (a + b) / 2.0;
            let (lo, hi) = ((st.mean[k] - st.std[k]).max(0.0), st.mean[k] + st.std[k]);
            if st.n > 1 && st.std[k] > 0.0 {
                let cap = (b - a) * 0.3;
                let ink = chart::INK.stroke_width(2);
                c.draw_series([
                    PathElement::new(vec![(cx, lo), (cx, hi)], ink),
                    PathElement::new(vec![(cx - cap, hi), (cx + cap, hi)], ink),
                    PathElement::new(vec![(cx - cap, lo), (cx + cap, lo)], ink),
                ])?;
            }
            if st.n != runs {
                let label = format!("n={}", st.n);
                let style = TextStyle::from((chart::FONT, chart::TICK).into_font())
                    .pos(Pos::new(HPos::Center, VPos::Bottom));
                c.draw_series(std::iter::once(
                    EmptyElement::at((cx, hi.max(st.mean[k]))) + Text::new(label, (0, -4), style),
                ))?;
            }
        }
        Ok(())
    }
}

/// A filled diamond of radius `r` pixels around its anchor.
fn diamond(r: i32) -> Polygon<(i32, i32)> {
    Polygon::new(vec![(0, -r), (r, 0), (0, r), (-r, 0)], chart::INK.filled())
}

// ---------------------------------------------------------------------------------------
// Curves

/// Training curves: a column of panels (one per metric) per group, groups side by side at
/// most three to a row; per model the mean over seeds with a std band; dashed lines where
/// the curriculum stage changes.
pub(super) fn draw_curves(
    groups: &[CurveGroup],
    metrics: &[Metric],
    title: &str,
    subtitle: &str,
    path: &Path,
) -> Result<()> {
    if groups.is_empty() || metrics.is_empty() {
        bail!("{}: nothing to plot", path.display());
    }
    let ncols = groups.len().min(3);
    let nrows = groups.len().div_ceil(ncols);
    let panel_w: u32 = if ncols == 1 { 1000 } else { 560 };
    let block_h = 40 + 270 * metrics.len() as u32;
    let (w, h) = (panel_w * ncols as u32, 40 + block_h * nrows as u32);
    let (root, body) = canvas(path, w, h, title)?;
    let err = |e| anyhow!("plot {}: {e:?}", path.display());
    let body = body
        .titled(
            subtitle,
            (chart::FONT, chart::LABEL).into_font().color(&SOFT),
        )
        .map_err(err)?;
    let mut all: Vec<String> = groups
        .iter()
        .flat_map(|g| g.models.iter().map(|(m, _, _)| m.clone()))
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    all.sort_by_key(|m| model_rank(m));
    let others: Vec<String> = all
        .iter()
        .filter(|m| !KNOWN_MODELS.contains(&m.as_str()))
        .cloned()
        .collect();
    let cells = body.split_evenly((nrows, ncols));
    for (g, cell) in groups.iter().zip(cells.iter()) {
        // each panel's legend counts its own seeds (a campaign in flight has fewer in some)
        let cell = match &g.name {
            Some(name) => cell
                .titled(&format!("setup {name}"), (chart::FONT, chart::CAPTION))
                .map_err(err)?,
            None => cell.clone(),
        };
        let panels = cell.split_evenly((metrics.len(), 1));
        for (pi, (metric, area)) in metrics.iter().zip(panels.iter()).enumerate() {
            let p = CurvePanel {
                g,
                pi,
                metric: *metric,
                last: pi + 1 == metrics.len(),
                others: &others,
            };
            p.draw(area).map_err(err)?;
        }
    }
    root.present().map_err(err)?;
    Ok(())
}

struct CurvePanel<'a> {
    g: &'a CurveGroup,
    /// Which metric of the group's curves.
    pi: usize,
    metric: Metric,
    /// The bottom panel of its column carries the x description.
    last: bool,
    others: &'a [String],
}

impl CurvePanel<'_> {
    /// The y range: every mean +- std, from 0 except for the reward; MU at most 1.
    fn y_range(&self) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (_, _, curves) in &self.g.models {
            for &(_, m, s, _) in &curves[self.pi] {
                lo = lo.min(m - s);
                hi = hi.max(m + s);
            }
        }
        if !lo.is_finite() {
            (lo, hi) = (0.0, 1.0);
        }
        if self.metric != Metric::Reward {
            lo = lo.min(0.0);
        }
        let (ylo, mut yhi, _) = nice_range(lo, hi, 5);
        let ylo = if self.metric != Metric::Reward {
            0.0
        } else {
            ylo
        };
        if self.metric == Metric::Mu && yhi > 1.0 && hi <= 1.0 {
            yhi = 1.0;
        }
        (ylo, yhi)
    }

    fn draw(&self, area: &Area) -> Drawn {
        let (ylo, yhi) = self.y_range();
        let mut c = ChartBuilder::on(area)
            .margin(10)
            .x_label_area_size(if self.last { 44 } else { 24 })
            .y_label_area_size(72)
            .build_cartesian_2d(0.0..self.g.x_max, ylo..yhi)?;
        let x_desc = if self.last { "episodes" } else { "" };
        chart::mesh(&mut c, x_desc, self.metric.title())?;
        self.draw_stages(&mut c, ylo, yhi)?;
        for (m, n, curves) in &self.g.models {
            let color = model_color(m, self.others);
            let cv = &curves[self.pi];
            if cv.iter().any(|p| p.3 > 1) && cv.len() > 1 {
                let mut band: Vec<(f64, f64)> = cv.iter().map(|p| (p.0, p.1 + p.2)).collect();
                band.extend(cv.iter().rev().map(|p| (p.0, p.1 - p.2)));
                c.draw_series(std::iter::once(Polygon::new(band, color.mix(0.2).filled())))?;
            }
            let series = if cv.len() == 1 {
                c.draw_series(std::iter::once(
                    EmptyElement::at((cv[0].0, cv[0].1)) + Circle::new((0, 0), 4, color.filled()),
                ))?
            } else {
                c.draw_series(LineSeries::new(
                    cv.iter().map(|p| (p.0, p.1)),
                    color.stroke_width(2),
                ))?
            };
            if self.pi == 0 {
                series.label(model_label(m, *n)).legend(legend_line(color));
            }
        }
        self.draw_levels(&mut c)?;
        if self.pi == 0 {
            chart::legend(&mut c)?;
        }
        Ok(())
    }

    /// `--levels`: a dashed line at each fraction of the first model's final value, and a
    /// dot with the episode count where its curve first reaches it (the paper's Fig. 5).
    fn draw_levels(&self, c: &mut ChartContext<BitMapBackend, Xy>) -> Drawn {
        let Some(levels) = self.g.levels.get(self.pi) else {
            return Ok(());
        };
        let Some((lead, _, _)) = self.g.models.first() else {
            return Ok(());
        };
        let color = model_color(lead, self.others);
        let style = (chart::FONT, chart::TICK).into_font().color(&INK);
        for l in levels {
            c.draw_series(DashedLineSeries::new(
                [(0.0, l.value), (self.g.x_max, l.value)],
                8,
                5,
                color.mix(0.7).stroke_width(1),
            ))?;
            let text = match l.hit {
                Some(x) => format!("{:.0} % of final: {x} episodes", l.frac * 100.0),
                None => format!("{:.0} % of final: not reached", l.frac * 100.0),
            };
            let at = l.hit.unwrap_or(0.0);
            c.draw_series(std::iter::once(
                EmptyElement::at((at, l.value))
                    + Circle::new((0, 0), 5, color.filled())
                    + Text::new(text, (8, -18), style.clone()),
            ))?;
        }
        Ok(())
    }

    /// Dashed lines where a curriculum stage starts; the first panel names the stages.
    fn draw_stages(&self, c: &mut ChartContext<BitMapBackend, Xy>, ylo: f64, yhi: f64) -> Drawn {
        if self.g.marks.len() < 2 {
            return Ok(());
        }
        for (x, _) in self.g.marks.iter().filter(|(x, _)| *x > 0.0) {
            c.draw_series(DashedLineSeries::new(
                [(*x, ylo), (*x, yhi)],
                6,
                4,
                SOFT.stroke_width(1),
            ))?;
        }
        if self.pi == 0 {
            let style = (chart::FONT, chart::TICK).into_font().color(&SOFT);
            c.draw_series(self.g.marks.iter().enumerate().map(|(i, (x, s))| {
                // staggered in two rows so that close stages stay readable
                let dy = 4 + 16 * (i % 2) as i32;
                EmptyElement::at((*x, yhi)) + Text::new(s.clone(), (4, dy), style.clone())
            }))?;
        }
        Ok(())
    }
}
