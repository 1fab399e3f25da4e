//! `tending plot bars`: evaluation results.csv files, averaged per setup and model over
//! training seeds.

use super::*;

pub(super) const BAR_METRICS: [(&str, &str, &str); 3] = [
    ("parts", "parts delivered per episode", "parts delivered"),
    ("collisions", "collisions per episode", "collisions"),
    ("mu", "machine utilization MU", "MU"),
];

/// One `results.csv`: per setup, the mean over its rows (evaluation seeds) of
/// [parts delivered, collisions, MU].
#[derive(Debug, Clone)]
pub(super) struct EvalRun {
    pub(super) model: String,
    pub(super) setups: BTreeMap<String, [f64; 3]>,
}

pub(super) fn parse_eval(path: &Path, text: &str) -> Result<EvalRun> {
    let mut model = None;
    let mut acc: BTreeMap<String, ([f64; 3], usize)> = BTreeMap::new();
    for records::Line { line, record: r } in records::parse::<EvalResultRecord>(path, text)? {
        let m = r
            .model()
            .or_else(|| model_from_path(path))
            .ok_or_else(|| anyhow!("{}:{line}: empty `policy`", path.display()))?;
        match &model {
            None => model = Some(m),
            Some(prev) if *prev != m => bail!(
                "{}:{line}: policy `{m}` after `{prev}`: one model per file expected",
                path.display()
            ),
            _ => {}
        }
        if setup_key(&r.setup).is_none() {
            bail!(
                "{}:{line}: setup `{}` is not N.M_K",
                path.display(),
                r.setup
            );
        }
        let values = [
            finite(path, line, "parts_delivered", r.parts_delivered)?,
            finite(path, line, "collisions", r.collisions)?,
            finite(path, line, "mu", r.mu)?,
        ];
        let e = acc.entry(r.setup).or_insert(([0.0; 3], 0));
        for (sum, v) in e.0.iter_mut().zip(values) {
            *sum += v;
        }
        e.1 += 1;
    }
    Ok(EvalRun {
        model: model.expect("records::parse guarantees a row"),
        setups: acc
            .into_iter()
            .map(|(s, (sum, n))| (s, sum.map(|x| x / n as f64)))
            .collect(),
    })
}

/// Per setup and model: mean and std over runs (training seeds) of each metric.
#[derive(Debug, Clone)]
pub(super) struct BarStat {
    pub(super) setup: String,
    pub(super) model: String,
    pub(super) n: usize,
    pub(super) mean: [f64; 3],
    pub(super) std: [f64; 3],
}

pub(super) fn aggregate_bars(runs: &[EvalRun]) -> Vec<BarStat> {
    let mut by: BTreeMap<(String, String), Vec<[f64; 3]>> = BTreeMap::new();
    for r in runs {
        for (s, v) in &r.setups {
            by.entry((s.clone(), r.model.clone())).or_default().push(*v);
        }
    }
    let mut out: Vec<BarStat> = by
        .into_iter()
        .map(|((setup, model), vs)| {
            let mut mean = [0.0; 3];
            let mut std = [0.0; 3];
            for k in 0..3 {
                let xs: Vec<f64> = vs.iter().map(|v| v[k]).collect();
                (mean[k], std[k]) = mean_std(&xs);
            }
            BarStat {
                setup,
                model,
                n: vs.len(),
                mean,
                std,
            }
        })
        .collect();
    out.sort_by(|a, b| {
        setup_key(&a.setup)
            .cmp(&setup_key(&b.setup))
            .then_with(|| model_rank(&a.model).cmp(&model_rank(&b.model)))
    });
    out
}

/// The paper's MU for one experiment: (setup, model) -> MU.
pub(super) fn parse_paper(
    path: &Path,
    text: &str,
    exp: &str,
) -> Result<BTreeMap<(String, String), f64>> {
    let mut out = BTreeMap::new();
    for records::Line { line, record: r } in records::parse::<PaperMuRecord>(path, text)? {
        if r.experiment != exp {
            continue;
        }
        let (n, m, k) = setup_key(&r.setup).ok_or_else(|| {
            anyhow!(
                "{}:{line}: setup `{}` is not N.M_K",
                path.display(),
                r.setup
            )
        })?;
        out.insert(
            (format!("{n}.{m}_{k}"), r.model.to_ascii_lowercase()),
            finite(path, line, "mu", r.mu)?,
        );
    }
    Ok(out)
}

pub(super) fn check_inputs(files: &[PathBuf]) -> Result<()> {
    for f in files {
        if !f.exists() {
            if f.to_string_lossy().contains('*') {
                bail!("{}: no file matches this pattern", f.display());
            }
            bail!("{}: no such file", f.display());
        }
    }
    Ok(())
}

pub(super) fn run_bars(a: &BarsArgs) -> Result<()> {
    check_inputs(&a.files)?;
    let mut runs = vec![];
    for f in &a.files {
        let text =
            std::fs::read_to_string(f).with_context(|| format!("{}: cannot read", f.display()))?;
        runs.push(parse_eval(f, &text)?);
    }
    let stats = aggregate_bars(&runs);
    let paper = match (&a.paper, &a.experiment) {
        (Some(p), Some(e)) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("{}: cannot read", p.display()))?;
            parse_paper(p, &text, e)?
        }
        _ => BTreeMap::new(),
    };
    for (k, (suffix, ylabel, what)) in BAR_METRICS.iter().enumerate() {
        let path = PathBuf::from(format!("{}_{suffix}.png", a.out.display()));
        let title = if a.title.is_empty() {
            what.to_string()
        } else {
            format!("{}: {what}", a.title)
        };
        let marks = if k == 2 { Some(&paper) } else { None };
        draw_bars(&stats, k, &title, ylabel, marks, &path)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
