//! Mean and standard deviation tables in the paper's "mean (std)" style.

/// Mean and population standard deviation (the paper reports std across seeds).
pub fn mean_std(xs: &[f64]) -> (f64, f64) {
    if xs.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let v = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n;
    (m, v.sqrt())
}

/// "m (s)" with `prec` decimals.
pub fn fmt_ms(xs: &[f64], prec: usize) -> String {
    let (m, s) = mean_std(xs);
    format!("{m:.prec$} ({s:.prec$})")
}

/// A Markdown table from a header and rows.
pub fn markdown_table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut out = String::new();
    out += &format!("| {} |\n", header.join(" | "));
    out += &format!("|{}\n", header.iter().map(|_| "---|").collect::<String>());
    for r in rows {
        out += &format!("| {} |\n", r.join(" | "));
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn mean_std_of_known_values() {
        let (m, s) = super::mean_std(&[1.0, 2.0, 3.0, 4.0]);
        assert!((m - 2.5).abs() < 1e-12);
        assert!((s - 1.25f64.sqrt()).abs() < 1e-12);
        assert_eq!(super::fmt_ms(&[0.5, 0.7], 2), "0.60 (0.10)");
    }
}
