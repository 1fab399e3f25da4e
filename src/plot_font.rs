//! A small built-in bitmap font for the PNG plots, so labels need no font feature of
//! `plotters` (the workspace builds it without one) and no system font library.
//!
//! Each glyph is 5 pixels wide on a 9-row cell: rows 0-6 hold capitals and digits (baseline
//! under row 6), lower case has its x-height on rows 2-6 and descenders on rows 7-8. Text is
//! drawn by filling `scale` x `scale` squares, horizontally or rotated a quarter turn
//! counter-clockwise (reading upwards, for y-axis titles). Characters without a glyph are
//! drawn as a hollow box.

use plotters::prelude::*;

/// Glyph cell width and height in font pixels; the advance is one pixel more than the width.
const GLYPH_W: i32 = 5;
#[cfg(test)]
const GLYPH_H: i32 = 9;
const ADVANCE: i32 = GLYPH_W + 1;

/// Rows of a glyph as `#` (ink) and `.` (blank), separated by `|`; missing rows are blank.
fn glyph(c: char) -> &'static str {
    match c {
        ' ' => "",
        'A' => ".###.|#...#|#...#|#####|#...#|#...#|#...#",
        'B' => "####.|#...#|#...#|####.|#...#|#...#|####.",
        'C' => ".###.|#...#|#....|#....|#....|#...#|.###.",
        'D' => "####.|#...#|#...#|#...#|#...#|#...#|####.",
        'E' => "#####|#....|#....|####.|#....|#....|#####",
        'F' => "#####|#....|#....|####.|#....|#....|#....",
        'G' => ".###.|#...#|#....|#.###|#...#|#...#|.####",
        'H' => "#...#|#...#|#...#|#####|#...#|#...#|#...#",
        'I' => ".###.|..#..|..#..|..#..|..#..|..#..|.###.",
        'J' => "..###|...#.|...#.|...#.|...#.|#..#.|.##..",
        'K' => "#...#|#..#.|#.#..|##...|#.#..|#..#.|#...#",
        'L' => "#....|#....|#....|#....|#....|#....|#####",
        'M' => "#...#|##.##|#.#.#|#.#.#|#...#|#...#|#...#",
        'N' => "#...#|#...#|##..#|#.#.#|#..##|#...#|#...#",
        'O' => ".###.|#...#|#...#|#...#|#...#|#...#|.###.",
        'P' => "####.|#...#|#...#|####.|#....|#....|#....",
        'Q' => ".###.|#...#|#...#|#...#|#.#.#|#..#.|.##.#",
        'R' => "####.|#...#|#...#|####.|#.#..|#..#.|#...#",
        'S' => ".####|#....|#....|.###.|....#|....#|####.",
        'T' => "#####|..#..|..#..|..#..|..#..|..#..|..#..",
        'U' => "#...#|#...#|#...#|#...#|#...#|#...#|.###.",
        'V' => "#...#|#...#|#...#|#...#|#...#|.#.#.|..#..",
        'W' => "#...#|#...#|#...#|#.#.#|#.#.#|#.#.#|.#.#.",
        'X' => "#...#|#...#|.#.#.|..#..|.#.#.|#...#|#...#",
        'Y' => "#...#|#...#|.#.#.|..#..|..#..|..#..|..#..",
        'Z' => "#####|....#|...#.|..#..|.#...|#....|#####",
        'a' => ".....|.....|.###.|....#|.####|#...#|.####",
        'b' => "#....|#....|#.##.|##..#|#...#|#...#|####.",
        'c' => ".....|.....|.###.|#....|#....|#...#|.###.",
        'd' => "....#|....#|.##.#|#..##|#...#|#...#|.####",
        'e' => ".....|.....|.###.|#...#|#####|#....|.###.",
        'f' => "..##.|.#..#|.#...|###..|.#...|.#...|.#...",
        'g' => ".....|.....|.####|#...#|#...#|#...#|.####|....#|.###.",
        'h' => "#....|#....|#.##.|##..#|#...#|#...#|#...#",
        'i' => "..#..|.....|.##..|..#..|..#..|..#..|.###.",
        'j' => "...#.|.....|..##.|...#.|...#.|...#.|...#.|#..#.|.##..",
        'k' => "#....|#....|#..#.|#.#..|##...|#.#..|#..#.",
        'l' => ".##..|..#..|..#..|..#..|..#..|..#..|.###.",
        'm' => ".....|.....|##.#.|#.#.#|#.#.#|#.#.#|#.#.#",
        'n' => ".....|.....|#.##.|##..#|#...#|#...#|#...#",
        'o' => ".....|.....|.###.|#...#|#...#|#...#|.###.",
        'p' => ".....|.....|####.|#...#|#...#|#...#|####.|#....|#....",
        'q' => ".....|.....|.####|#...#|#...#|#...#|.####|....#|....#",
        'r' => ".....|.....|#.##.|##..#|#....|#....|#....",
        's' => ".....|.....|.####|#....|.###.|....#|####.",
        't' => ".#...|.#...|###..|.#...|.#...|.#..#|..##.",
        'u' => ".....|.....|#...#|#...#|#...#|#..##|.##.#",
        'v' => ".....|.....|#...#|#...#|#...#|.#.#.|..#..",
        'w' => ".....|.....|#...#|#...#|#.#.#|#.#.#|.#.#.",
        'x' => ".....|.....|#...#|.#.#.|..#..|.#.#.|#...#",
        'y' => ".....|.....|#...#|#...#|#...#|#...#|.####|....#|.###.",
        'z' => ".....|.....|#####|...#.|..#..|.#...|#####",
        '0' => ".###.|#...#|#..##|#.#.#|##..#|#...#|.###.",
        '1' => "..#..|.##..|..#..|..#..|..#..|..#..|.###.",
        '2' => ".###.|#...#|....#|...#.|..#..|.#...|#####",
        '3' => "####.|....#|....#|.###.|....#|....#|####.",
        '4' => "...#.|..##.|.#.#.|#..#.|#####|...#.|...#.",
        '5' => "#####|#....|####.|....#|....#|#...#|.###.",
        '6' => "..##.|.#...|#....|####.|#...#|#...#|.###.",
        '7' => "#####|....#|...#.|..#..|.#...|.#...|.#...",
        '8' => ".###.|#...#|#...#|.###.|#...#|#...#|.###.",
        '9' => ".###.|#...#|#...#|.####|....#|...#.|.##..",
        '.' => ".....|.....|.....|.....|.....|.##..|.##..",
        ',' => ".....|.....|.....|.....|.....|.....|.##..|..#..|.#...",
        ':' => ".....|.##..|.##..|.....|.##..|.##..",
        ';' => ".....|.##..|.##..|.....|.....|.##..|.##..|..#..|.#...",
        '-' => ".....|.....|.....|.###.",
        '_' => ".....|.....|.....|.....|.....|.....|.....|#####",
        '+' => ".....|..#..|..#..|#####|..#..|..#..",
        '=' => ".....|.....|#####|.....|#####",
        '(' => "...#.|..#..|.#...|.#...|.#...|..#..|...#.",
        ')' => ".#...|..#..|...#.|...#.|...#.|..#..|.#...",
        '[' => ".###.|.#...|.#...|.#...|.#...|.#...|.###.",
        ']' => ".###.|...#.|...#.|...#.|...#.|...#.|.###.",
        '/' => "....#|....#|...#.|..#..|.#...|#....|#....",
        '%' => "##...|##..#|...#.|..#..|.#...|#..##|...##",
        '\'' => "..#..|..#..|.#...",
        '"' => ".#.#.|.#.#.|.#.#.",
        '!' => "..#..|..#..|..#..|..#..|..#..|.....|..#..",
        '?' => ".###.|#...#|....#|...#.|..#..|.....|..#..",
        '<' => "...#.|..#..|.#...|#....|.#...|..#..|...#.",
        '>' => ".#...|..#..|...#.|....#|...#.|..#..|.#...",
        '#' => ".#.#.|.#.#.|#####|.#.#.|#####|.#.#.|.#.#.",
        '*' => ".....|..#..|#.#.#|.###.|#.#.#|..#..",
        '|' => "..#..|..#..|..#..|..#..|..#..|..#..|..#..|..#..",
        '~' => ".....|.....|.#...|#.#.#|...#.",
        '&' => ".##..|#..#.|#.#..|.#...|#.#.#|#..#.|.##.#",
        _ => "#####|#...#|#...#|#...#|#...#|#...#|#####",
    }
}

/// Ink pixels (column, row) of a character's glyph.
fn ink(c: char) -> impl Iterator<Item = (i32, i32)> {
    glyph(c).split('|').enumerate().flat_map(|(r, row)| {
        row.bytes()
            .enumerate()
            .filter(|(_, b)| *b == b'#')
            .map(move |(col, _)| (col as i32, r as i32))
    })
}

/// Width in pixels of `text` at `scale` (no trailing spacing).
pub fn text_width(text: &str, scale: i32) -> i32 {
    let n = text.chars().count() as i32;
    if n == 0 {
        0
    } else {
        (n * ADVANCE - 1) * scale
    }
}

/// Height in pixels of a line of text at `scale` (capital height, descenders excluded).
pub fn text_height(scale: i32) -> i32 {
    7 * scale
}

/// Horizontal anchor of a text position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    Left,
    Center,
    Right,
}

/// Draws `text` with its capital top at `y`, `x` meaning its left, centre or right edge.
pub fn draw_text<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    text: &str,
    (x, y): (i32, i32),
    align: Align,
    scale: i32,
    color: RGBColor,
) {
    let w = text_width(text, scale);
    let x0 = match align {
        Align::Left => x,
        Align::Center => x - w / 2,
        Align::Right => x - w,
    };
    for (i, c) in text.chars().enumerate() {
        let cx = x0 + i as i32 * ADVANCE * scale;
        for (col, row) in ink(c) {
            let px = cx + col * scale;
            let py = y + row * scale;
            // A failed pixel only loses a pixel; the plot still gets written. (The fill
            // covers the rectangle without its right and bottom edges.)
            let _ = area.draw(&Rectangle::new(
                [(px, py), (px + scale, py + scale)],
                color.filled(),
            ));
        }
    }
}

/// Draws `text` reading upwards (rotated a quarter turn counter-clockwise), centred on
/// `y`, with the capitals' top edge at `x`.
pub fn draw_text_up<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    text: &str,
    (x, y): (i32, i32),
    scale: i32,
    color: RGBColor,
) {
    let w = text_width(text, scale);
    let y0 = y + w / 2;
    for (i, c) in text.chars().enumerate() {
        let along = i as i32 * ADVANCE * scale;
        for (col, row) in ink(c) {
            let px = x + row * scale;
            let py = y0 - along - col * scale - (scale - 1);
            let _ = area.draw(&Rectangle::new(
                [(px, py), (px + scale, py + scale)],
                color.filled(),
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_glyph_fits_its_cell() {
        for c in (32u8..127).map(char::from) {
            let rows: Vec<&str> = glyph(c).split('|').collect();
            assert!(
                rows.len() as i32 <= GLYPH_H,
                "{c:?} has {} rows",
                rows.len()
            );
            for r in rows {
                assert!(
                    r.is_empty() || r.len() as i32 == GLYPH_W,
                    "{c:?} row {r:?} is not {GLYPH_W} wide"
                );
                assert!(r.bytes().all(|b| b == b'#' || b == b'.'), "{c:?} row {r:?}");
            }
        }
        assert_eq!(text_width("ab", 2), 22);
        assert_eq!(text_width("", 2), 0);
    }
}
