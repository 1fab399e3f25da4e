//! RGB frames of an environment for Python (`Sim.render`).

use numpy::ndarray::Array3;
use sim::Env;

/// An RGB frame of `env`, `px` x `px`, in the colours of `tending sim --render` (the
/// paper's Fig. 3: robots red with a yellow dot when carrying, ready machines green, idle
/// ones pale green, storages blue; a bar along the top edge shows episode time). A small
/// rasteriser of our own: the CLI's plotters renderer lives in the binary crate.
pub(crate) fn render_rgb(env: &Env, px: usize) -> Array3<u8> {
    let mut img = Array3::<u8>::from_elem((px, px, 3), 255);
    let room = env.config().world.room_size;
    let s = px as f32 / room;
    let to_px = |p: [f32; 2]| ((p[0] + room / 2.0) * s, (room / 2.0 - p[1]) * s);
    let clamp = |v: f32| (v.max(0.0) as usize).min(px);
    let fill_rect = |img: &mut Array3<u8>, x0: f32, y0: f32, x1: f32, y1: f32, c: [u8; 3]| {
        for y in clamp(y0)..clamp(y1) {
            for x in clamp(x0)..clamp(x1) {
                for k in 0..3 {
                    img[[y, x, k]] = c[k];
                }
            }
        }
    };
    let fill_disc = |img: &mut Array3<u8>, cx: f32, cy: f32, r: f32, c: [u8; 3]| {
        for y in clamp(cy - r)..clamp(cy + r + 1.0) {
            for x in clamp(cx - r)..clamp(cx + r + 1.0) {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                if dx * dx + dy * dy <= r * r {
                    for k in 0..3 {
                        img[[y, x, k]] = c[k];
                    }
                }
            }
        }
    };
    let mut boxes: Vec<([f32; 2], [f32; 2], [u8; 3])> = Vec::new();
    boxes.extend(env.storages().map(|b| (b.centre, b.half, [60, 90, 220])));
    boxes.extend(env.machines().map(|m| {
        let col = if m.part_ready {
            [30, 170, 60]
        } else {
            [170, 210, 170]
        };
        (m.centre, m.half, col)
    }));
    for (c, h, col) in boxes {
        let (x0, y0) = to_px([c[0] - h[0], c[1] + h[1]]);
        let (x1, y1) = to_px([c[0] + h[0], c[1] - h[1]]);
        fill_rect(&mut img, x0, y0, x1, y1, col);
    }
    let rp = (env.sizes().robot_radius * s).max(2.0);
    for r in env.robots() {
        let (cx, cy) = to_px(r.pos);
        fill_disc(&mut img, cx, cy, rp, [210, 40, 40]);
        if r.has_part {
            fill_disc(&mut img, cx, cy, (rp / 2.0).max(1.0), [250, 220, 40]);
        }
    }
    // Walls (2 px) and the episode-time bar.
    let w = px as f32;
    let border = (w / 230.0).max(1.0);
    for (x0, y0, x1, y1) in [
        (0.0, 0.0, w, border),
        (0.0, w - border, w, w),
        (0.0, 0.0, border, w),
        (w - border, 0.0, w, w),
    ] {
        fill_rect(&mut img, x0, y0, x1, y1, [0, 0, 0]);
    }
    let frac = env.steps() as f32 / env.config().world.episode_steps.max(1) as f32;
    fill_rect(
        &mut img,
        0.0,
        0.0,
        w * frac.min(1.0),
        2.0 * border,
        [0, 0, 0],
    );
    img
}
