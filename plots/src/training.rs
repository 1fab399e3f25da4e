//! Training curves as PNG (`tending train`'s curve.png), through plotters' chart layer.
//!
//! Top panel: mean team reward per update (thin blue) and its moving average over 10
//! updates (thick red). Bottom panel: machine utilization MU (thin green, moving average
//! thick dark green) on a fixed 0..1 scale. Vertical black lines mark curriculum stage
//! changes; the x axis is episodes in both panels. Title, axis labels and legend on the
//! figure ([`crate::chart`]).

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use std::path::Path;

use crate::chart;

/// One point per update.
#[derive(Debug, Clone, Copy)]
pub struct CurvePoint {
    pub episodes: f64,
    pub reward: f64,
    pub mu: f64,
}

fn moving_average(xs: &[f64], w: usize) -> Vec<f64> {
    (0..xs.len())
        .map(|i| {
            let lo = (i + 1).saturating_sub(w);
            let s = &xs[lo..=i];
            s.iter().sum::<f64>() / s.len() as f64
        })
        .collect()
}

/// One panel: a thin per-update series, its moving average, stage lines, a legend.
struct Panel<'a> {
    caption: &'a str,
    y_desc: &'a str,
    series: &'a str,
    y: (f64, f64),
    thin: RGBColor,
    thick: RGBColor,
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &Panel,
    points: &[(f64, f64)],
    stage_starts: &[f64],
    x_max: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (lo, hi) = panel.y;
    let mut c = ChartBuilder::on(area)
        .caption(panel.caption, (chart::FONT, chart::CAPTION))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(0.0..x_max, lo..hi)?;
    chart::mesh(&mut c, "episodes", panel.y_desc)?;
    for (i, &s) in stage_starts.iter().enumerate() {
        let line = c.draw_series(LineSeries::new([(s, lo), (s, hi)], BLACK.stroke_width(2)))?;
        if i == 0 {
            line.label("curriculum stage change").legend(|(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2))
            });
        }
    }
    let thin = panel.thin;
    c.draw_series(LineSeries::new(points.iter().copied(), thin))?
        .label(panel.series)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], thin));
    let ys: Vec<f64> = points.iter().map(|p| p.1).collect();
    let thick = panel.thick.stroke_width(3);
    c.draw_series(LineSeries::new(
        points
            .iter()
            .zip(moving_average(&ys, 10))
            .map(|(p, m)| (p.0, m)),
        thick,
    ))?
    .label("moving average, 10 updates")
    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], thick));
    chart::legend(&mut c)?;
    Ok(())
}

pub fn plot_training(points: &[CurvePoint], stage_starts: &[f64], path: &Path) -> Result<()> {
    if points.is_empty() {
        return Ok(());
    }
    chart::init();
    let e = |x: DrawingAreaErrorKind<_>| anyhow!("plot {}: {x:?}", path.display());
    let root = BitMapBackend::new(path, (900, 720)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let root = root
        .titled("Training", (chart::FONT, chart::TITLE))
        .map_err(e)?;
    let (top, bottom) = root.split_vertically(360);
    let x_max = points.last().map(|p| p.episodes).unwrap_or(1.0).max(1.0);
    let (mut lo, mut hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.reward), b.max(p.reward))
        });
    if (hi - lo).abs() < 1e-9 {
        lo -= 1.0;
        hi += 1.0;
    }
    let pad = 0.05 * (hi - lo);
    let reward = Panel {
        caption: "mean team reward per update",
        y_desc: "team reward",
        series: "per update",
        y: (lo - pad, hi + pad),
        thin: RGBColor(120, 150, 230),
        thick: RGBColor(220, 30, 30),
    };
    let rewards: Vec<(f64, f64)> = points.iter().map(|p| (p.episodes, p.reward)).collect();
    draw_panel(&top, &reward, &rewards, stage_starts, x_max).map_err(e)?;
    let mu = Panel {
        caption: "machine utilization (MU)",
        y_desc: "MU",
        series: "per update",
        y: (0.0, 1.0),
        thin: RGBColor(120, 200, 120),
        thick: RGBColor(0, 110, 0),
    };
    let mus: Vec<(f64, f64)> = points.iter().map(|p| (p.episodes, p.mu)).collect();
    draw_panel(&bottom, &mu, &mus, stage_starts, x_max).map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_average_and_png() {
        assert_eq!(moving_average(&[1.0, 3.0, 5.0], 2), vec![1.0, 2.0, 4.0]);
        let pts: Vec<CurvePoint> = (0..30)
            .map(|i| CurvePoint {
                episodes: (i * 8) as f64,
                reward: -50.0 + i as f64,
                mu: i as f64 / 40.0,
            })
            .collect();
        let p = std::env::temp_dir().join(format!("tending-curve-{}.png", std::process::id()));
        plot_training(&pts, &[80.0], &p).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        std::fs::remove_file(&p).ok();
    }
}
