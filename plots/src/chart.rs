//! What every PNG of `tending` shares: the bundled font and the chart style.
//!
//! Text is rendered by plotters' `ab_glyph` feature from DejaVu Sans, bundled in the binary
//! (`assets/fonts/`, Bitstream Vera licence beside it), so a figure looks the same on any
//! machine and needs no system fonts (docs/adr/0010-plotting.md).

use std::sync::Once;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;

static DEJAVU_SANS: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// The family every chart asks for.
pub const FONT: &str = "sans-serif";

/// Title, axis-label and tick sizes in pixels.
pub const TITLE: u32 = 24;
pub const CAPTION: u32 = 18;
pub const LABEL: u32 = 15;
pub const TICK: u32 = 13;

pub const INK: RGBColor = RGBColor(20, 20, 20);
pub const GRID: RGBColor = RGBColor(225, 225, 225);

/// Twelve colours far enough apart to tell methods apart (an ablation has many).
pub const PALETTE: [RGBColor; 12] = [
    RGBColor(200, 40, 40),
    RGBColor(230, 140, 20),
    RGBColor(40, 90, 200),
    RGBColor(30, 150, 60),
    RGBColor(140, 60, 170),
    RGBColor(90, 90, 90),
    RGBColor(0, 170, 190),
    RGBColor(240, 60, 170),
    RGBColor(150, 110, 40),
    RGBColor(120, 190, 40),
    RGBColor(20, 30, 100),
    RGBColor(250, 200, 30),
];

/// The label of x tick `v` on a category axis (category i centred at x = i): the i-th
/// name at whole numbers, nothing between them.
pub fn category_label(names: &[String], v: f64) -> String {
    let i = v.round();
    if (v - i).abs() < 1e-6 && i >= 0.0 {
        names.get(i as usize).cloned().unwrap_or_default()
    } else {
        String::new()
    }
}

/// A tick label without plotters' default trailing ".0": 2000 for 2000.0, 0.25 for 0.25
/// (at most 3 decimals, trailing zeros cut).
pub fn number_label(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        return format!("{:.0}", v.round() + 0.0); // + 0.0: no "-0"
    }
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Register the bundled font with plotters (once per process; before drawing any text).
pub fn init() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let ok = plotters::style::register_font(FONT, FontStyle::Normal, DEJAVU_SANS).is_ok();
        debug_assert!(ok, "the bundled font parses");
    });
}

/// The coordinates of every chart here: f64 on both axes.
pub type Xy = Cartesian2d<RangedCoordf64, RangedCoordf64>;
type Drawn<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// Light grid, ticks and both axis descriptions.
pub fn mesh<'a, DB: DrawingBackend + 'a>(
    c: &mut ChartContext<'a, DB, Xy>,
    x: &str,
    y: &str,
) -> Drawn<DB> {
    c.configure_mesh()
        .light_line_style(TRANSPARENT)
        .bold_line_style(GRID)
        .x_labels(6)
        .x_label_formatter(&|v| number_label(*v))
        .y_label_formatter(&|v| number_label(*v))
        .x_desc(x)
        .y_desc(y)
        .axis_desc_style((FONT, LABEL))
        .label_style((FONT, TICK))
        .draw()
}

/// The legend box of the labelled series, lower right.
pub fn legend<'a, DB: DrawingBackend + 'a>(c: &mut ChartContext<'a, DB, Xy>) -> Drawn<DB> {
    c.configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(INK)
        .label_font((FONT, TICK))
        .draw()
}

#[cfg(test)]
mod tests {
    #[test]
    fn tick_labels_drop_trailing_zeros() {
        use super::number_label;
        assert_eq!(number_label(2000.0), "2000");
        assert_eq!(number_label(-0.0), "0");
        assert_eq!(number_label(0.25), "0.25");
        assert_eq!(number_label(-150.5), "-150.5");
        assert_eq!(number_label(0.1 + 0.2), "0.3");
    }

    #[test]
    fn the_bundled_font_renders_text() {
        use plotters::prelude::*;
        super::init();
        let (w, h) = (200u32, 60u32);
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            root.draw(&Text::new("tending 0.5", (10, 10), (super::FONT, 30)))
                .unwrap();
            root.present().unwrap();
        }
        assert!(buf.iter().any(|&b| b < 128), "no glyph pixels drawn");
    }
}
