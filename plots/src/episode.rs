//! Draw episodes so a person can watch them: GIF animation, SVG of the last frame, or PNG
//! frames. Colours follow the paper's Fig. 3: robots red, machines green, storages blue.

use anyhow::{bail, Result};
use plotters::prelude::*;
use sim::{Env, ScenarioConfig};
use std::path::Path;

#[derive(Debug, Clone)]
pub struct Frame {
    pub robots: Vec<([f32; 2], bool)>,
    pub machines: Vec<([f32; 2], [f32; 2], bool)>,
    pub storages: Vec<([f32; 2], [f32; 2])>,
    pub robot_radius: f32,
    pub step: u32,
    pub delivered: u32,
}

impl Frame {
    pub fn capture(env: &Env) -> Self {
        Frame {
            robots: env.robots().map(|r| (r.pos, r.has_part)).collect(),
            machines: env
                .machines()
                .map(|m| (m.centre, m.half, m.part_ready))
                .collect(),
            storages: env.storages().map(|s| (s.centre, s.half)).collect(),
            robot_radius: env.sizes().robot_radius,
            step: env.steps(),
            delivered: env.metrics().parts_delivered,
        }
    }
}

const PX: u32 = 460;

fn draw<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    room: f32,
    f: &Frame,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let s = PX as f32 / room;
    let to = |p: [f32; 2]| -> (i32, i32) {
        (
            ((p[0] + room / 2.0) * s) as i32,
            ((room / 2.0 - p[1]) * s) as i32,
        )
    };
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("drawing failed: {e:?}");
    area.fill(&WHITE).map_err(err)?;
    area.draw(&Rectangle::new(
        [(0, 0), (PX as i32 - 1, PX as i32 - 1)],
        BLACK.stroke_width(4),
    ))
    .map_err(err)?;
    for &(c, h) in &f.storages {
        let (a, b) = (
            to([c[0] - h[0], c[1] + h[1]]),
            to([c[0] + h[0], c[1] - h[1]]),
        );
        area.draw(&Rectangle::new([a, b], RGBColor(60, 90, 220).filled()))
            .map_err(err)?;
    }
    for &(c, h, ready) in &f.machines {
        let (a, b) = (
            to([c[0] - h[0], c[1] + h[1]]),
            to([c[0] + h[0], c[1] - h[1]]),
        );
        let col = if ready {
            RGBColor(30, 170, 60)
        } else {
            RGBColor(170, 210, 170)
        };
        area.draw(&Rectangle::new([a, b], col.filled()))
            .map_err(err)?;
    }
    let rp = (f.robot_radius * s).max(2.0) as i32;
    for &(p, part) in &f.robots {
        area.draw(&Circle::new(to(p), rp, RGBColor(210, 40, 40).filled()))
            .map_err(err)?;
        if part {
            area.draw(&Circle::new(
                to(p),
                (rp / 2).max(1),
                RGBColor(250, 220, 40).filled(),
            ))
            .map_err(err)?;
        }
    }
    // Progress bar along the top edge: episode time; ticks below it: parts delivered.
    let w = (PX as f32 * f.step as f32 / 200.0).min(PX as f32) as i32;
    area.draw(&Rectangle::new([(0, 0), (w, 4)], BLACK.filled()))
        .map_err(err)?;
    for k in 0..f.delivered.min(90) as i32 {
        area.draw(&Rectangle::new(
            [(4 + k * 5, 8), (6 + k * 5, 14)],
            RGBColor(60, 90, 220).filled(),
        ))
        .map_err(err)?;
    }
    Ok(())
}

/// Write `frames`: `.gif` animation (10 fps, real time), `.svg` last frame, or a directory
/// (path ending in `/` or an existing directory) of PNG frames.
pub fn write(path: &Path, cfg: &ScenarioConfig, frames: &[Frame]) -> Result<()> {
    let room = cfg.world.room_size;
    if frames.is_empty() {
        bail!("nothing to render");
    }
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    if let Some(parent) = path.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent)?;
        }
    }
    match ext {
        "gif" => {
            let delay = (cfg.world.dt * 1000.0) as u32;
            let root = BitMapBackend::gif(path, (PX, PX), delay)?.into_drawing_area();
            for f in frames {
                draw(&root, room, f)?;
                root.present()?;
            }
        }
        "svg" => {
            let root = SVGBackend::new(path, (PX, PX)).into_drawing_area();
            draw(&root, room, frames.last().expect("non-empty"))?;
            root.present()?;
        }
        "" => {
            std::fs::create_dir_all(path)?;
            for (i, f) in frames.iter().enumerate() {
                let p = path.join(format!("frame_{i:04}.png"));
                let root = BitMapBackend::new(&p, (PX, PX)).into_drawing_area();
                draw(&root, room, f)?;
                root.present()?;
            }
        }
        other => bail!(
            "--render {}: unknown extension `{other}` (use .gif, .svg or a directory)",
            path.display()
        ),
    }
    Ok(())
}
