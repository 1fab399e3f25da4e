//! Training curves as PNG (plotters bitmap backend, no font: the curves are unlabeled and
//! their legend is written next to them in Markdown).
//!
//! Top panel: mean team reward per update (thin blue) and its moving average over 10
//! updates (thick red). Bottom panel: machine utilization MU (thin green, moving average
//! thick dark green) on a fixed 0..1 scale with grey lines at 0.25, 0.5, 0.75. Vertical
//! black lines mark curriculum stage changes; the x axis is episodes in both panels.

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use std::path::Path;

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

pub fn plot_training(points: &[CurvePoint], stage_starts: &[f64], path: &Path) -> Result<()> {
    if points.is_empty() {
        return Ok(());
    }
    let e = |x: DrawingAreaErrorKind<_>| anyhow!("plot {}: {x:?}", path.display());
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let (top, bottom) = root.split_vertically(360);
    let x_max = points.last().map(|p| p.episodes).unwrap_or(1.0).max(1.0);
    let rewards: Vec<f64> = points.iter().map(|p| p.reward).collect();
    let mus: Vec<f64> = points.iter().map(|p| p.mu).collect();
    let (mut lo, mut hi) = rewards
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &r| {
            (a.min(r), b.max(r))
        });
    if (hi - lo).abs() < 1e-9 {
        lo -= 1.0;
        hi += 1.0;
    }
    let pad = 0.05 * (hi - lo);
    let mut c = ChartBuilder::on(&top)
        .margin(12)
        .build_cartesian_2d(0.0..x_max, (lo - pad)..(hi + pad))
        .map_err(e)?;
    if lo < 0.0 && hi > 0.0 {
        c.draw_series(LineSeries::new(
            [(0.0, 0.0), (x_max, 0.0)],
            RGBColor(180, 180, 180),
        ))
        .map_err(e)?;
    }
    for &s in stage_starts {
        c.draw_series(LineSeries::new(
            [(s, lo - pad), (s, hi + pad)],
            BLACK.stroke_width(2),
        ))
        .map_err(e)?;
    }
    c.draw_series(LineSeries::new(
        points.iter().map(|p| (p.episodes, p.reward)),
        RGBColor(120, 150, 230),
    ))
    .map_err(e)?;
    c.draw_series(LineSeries::new(
        points
            .iter()
            .zip(moving_average(&rewards, 10))
            .map(|(p, m)| (p.episodes, m)),
        RED.stroke_width(3),
    ))
    .map_err(e)?;
    c.plotting_area()
        .draw(&Rectangle::new(
            [(0.0, lo - pad), (x_max, hi + pad)],
            BLACK.stroke_width(1),
        ))
        .map_err(e)?;

    let mut m = ChartBuilder::on(&bottom)
        .margin(12)
        .build_cartesian_2d(0.0..x_max, 0.0..1.0f64)
        .map_err(e)?;
    for y in [0.25, 0.5, 0.75] {
        m.draw_series(LineSeries::new(
            [(0.0, y), (x_max, y)],
            RGBColor(200, 200, 200),
        ))
        .map_err(e)?;
    }
    for &s in stage_starts {
        m.draw_series(LineSeries::new([(s, 0.0), (s, 1.0)], BLACK.stroke_width(2)))
            .map_err(e)?;
    }
    m.draw_series(LineSeries::new(
        points.iter().map(|p| (p.episodes, p.mu)),
        RGBColor(120, 200, 120),
    ))
    .map_err(e)?;
    m.draw_series(LineSeries::new(
        points
            .iter()
            .zip(moving_average(&mus, 10))
            .map(|(p, v)| (p.episodes, v)),
        RGBColor(0, 110, 0).stroke_width(3),
    ))
    .map_err(e)?;
    m.plotting_area()
        .draw(&Rectangle::new(
            [(0.0, 0.0), (x_max, 1.0)],
            BLACK.stroke_width(1),
        ))
        .map_err(e)?;
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
