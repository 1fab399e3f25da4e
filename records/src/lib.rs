//! What tending's commands report, one definition for every writer and reader:
//!
//! * [`report`]: a run's numbers (`tending sim`, `tending eval`) and their Markdown cells;
//!   [`stats`]: the paper's "mean (std)" and Markdown tables.
//! * The CSV files tending writes and reads, one typed record per file kind (csv + serde;
//!   columns are found by header name, never by index):
//!   * [`TrainLogRecord`]: a training run's `log.csv` (`tending train`, `tending plot curves`).
//!   * [`EvalResultRecord`]: `tending eval`'s `results.csv` (`tending plot bars|pareto`).
//!   * [`PaperMuRecord`]: the paper's MU values (`bench/experiments/paper_mu.csv`).
//!   * [`PartsBoundRecord`]: `tending bound`'s `bound.csv` (`tending plot limits`).
//!
//! Columns added by later versions are `Option`s, so files already committed (docs/,
//! policy/pretrained/) still read; the tests beside each record read them.

mod eval_results;
mod paper_mu;
mod parts_bound;
pub mod report;
pub mod stats;
mod train_log;

pub use eval_results::EvalResultRecord;
pub use paper_mu::PaperMuRecord;
pub use parts_bound::PartsBoundRecord;
pub use report::Numbers;
pub use train_log::TrainLogRecord;

use anyhow::{anyhow, bail, Result};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::path::Path;

/// One data row and the 1-based line of the file it came from (for error messages).
#[derive(Debug, Clone, PartialEq)]
pub struct Line<T> {
    pub line: u64,
    pub record: T,
}

/// The records of `text` (the contents of `path`). Errors name the file, the line and the
/// column; an empty file or one without data rows is an error.
pub fn parse<T: DeserializeOwned>(path: &Path, text: &str) -> Result<Vec<Line<T>>> {
    if text.trim().is_empty() {
        bail!("{}: empty file (expected a CSV header)", path.display());
    }
    let mut r = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let header = r
        .headers()
        .map_err(|e| anyhow!("{}: header: {e}", path.display()))?
        .clone();
    let mut out = vec![];
    for rec in r.records() {
        let rec = rec.map_err(|e| anyhow!(describe(path, &header, None, &e)))?;
        let line = rec.position().map_or(0, |p| p.line());
        let record = rec
            .deserialize(Some(&header))
            .map_err(|e| anyhow!(describe(path, &header, Some(line), &e)))?;
        out.push(Line { line, record });
    }
    if out.is_empty() {
        bail!("{}: no data rows", path.display());
    }
    Ok(out)
}

/// Reads `path` and parses its records.
pub fn read<T: DeserializeOwned>(path: &Path) -> Result<Vec<Line<T>>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow!("{}: cannot read: {e}", path.display()))?;
    parse(path, &text)
}

/// The CSV text of `records`, header from the field names.
pub fn to_text<T: Serialize>(records: &[T]) -> Result<String> {
    let mut w = csv::Writer::from_writer(vec![]);
    for r in records {
        w.serialize(r)?;
    }
    Ok(String::from_utf8(w.into_inner()?)?)
}

/// `v` as a checked number: finite, else an error naming the file, line and column.
pub fn finite(path: &Path, line: u64, column: &str, v: f64) -> Result<f64> {
    if !v.is_finite() {
        bail!("{}:{line}: column `{column}` is {v}", path.display());
    }
    Ok(v)
}

fn describe(path: &Path, header: &csv::StringRecord, line: Option<u64>, e: &csv::Error) -> String {
    let line = line.or(e.position().map(|p| p.line())).unwrap_or(0);
    match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!(
            "{}:{line}: {len} fields, the header has {expected_len}",
            path.display()
        ),
        csv::ErrorKind::Deserialize { err, .. } => match err.field() {
            Some(i) => format!(
                "{}:{line}: column `{}`: {}",
                path.display(),
                header.get(i as usize).unwrap_or("?"),
                err.kind()
            ),
            None => format!(
                "{}:{line}: {} (columns: {})",
                path.display(),
                err.kind(),
                header.iter().collect::<Vec<_>>().join(",")
            ),
        },
        _ => format!("{}:{line}: {e}", path.display()),
    }
}

/// Fixed-decimal number columns (log.csv keeps the precision it has always had).
pub(crate) mod decimals {
    use serde::Serializer;

    /// A number column that may be absent (a column older files lack).
    pub trait Number {
        fn write<S: Serializer>(&self, decimals: usize, s: S) -> Result<S::Ok, S::Error>;
    }
    impl Number for f64 {
        fn write<S: Serializer>(&self, decimals: usize, s: S) -> Result<S::Ok, S::Error> {
            s.collect_str(&format_args!("{self:.decimals$}"))
        }
    }
    impl Number for Option<f64> {
        fn write<S: Serializer>(&self, decimals: usize, s: S) -> Result<S::Ok, S::Error> {
            match self {
                Some(v) => v.write(decimals, s),
                None => s.serialize_none(),
            }
        }
    }

    macro_rules! fixed {
        ($($name:ident = $d:literal),*) => {$(
            pub fn $name<N: Number, S: Serializer>(v: &N, s: S) -> Result<S::Ok, S::Error> {
                v.write($d, s)
            }
        )*};
    }
    fixed!(dp1 = 1, dp3 = 3, dp4 = 4, dp5 = 5, dp6 = 6);
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, Deserialize, PartialEq)]
    struct R {
        name: String,
        x: f64,
        y: Option<f64>,
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let p = Path::new("dir/f.csv");
        let e = parse::<R>(p, "").unwrap_err().to_string();
        assert!(e.contains("dir/f.csv") && e.contains("empty"), "{e}");
        let e = parse::<R>(p, "name,x\n").unwrap_err().to_string();
        assert!(e.contains("no data rows"), "{e}");
        let e = parse::<R>(p, "name,x\na,1\nb,z\n").unwrap_err().to_string();
        assert!(e.contains("dir/f.csv:3") && e.contains("`x`"), "{e}");
        let e = parse::<R>(p, "name,x\na,1,2\n").unwrap_err().to_string();
        assert!(e.contains("f.csv:2") && e.contains("3 fields"), "{e}");
        let e = parse::<R>(p, "name,y\na,1\n").unwrap_err().to_string();
        assert!(e.contains("f.csv:2") && e.contains("`x`"), "{e}");
        assert!(finite(p, 4, "x", f64::NAN)
            .unwrap_err()
            .to_string()
            .contains("f.csv:4"));
    }

    #[test]
    fn missing_optional_columns_and_extra_columns_read() {
        let rows = parse::<R>(Path::new("f"), "name, x ,extra\na, 1.5 ,q\n\nb,2,r\n").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].line, 3);
        assert_eq!(
            rows[0].record,
            R {
                name: "a".into(),
                x: 1.5,
                y: None
            }
        );
    }
}
