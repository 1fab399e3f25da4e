//! `tending plot`: PNG figures of the paper's experiments (section V) from the files
//! `tending eval` and `tending train` write.
//!
//! * `bars`: evaluation `results.csv` files, one per trained model (a scripted baseline has
//!   one file and no training seeds). Per file, rows of the same setup (evaluation seeds) are
//!   averaged; then, per setup and model, mean and population std over files, i.e. over
//!   training seeds, the paper's "average and std as error bars" (Fig. 4, 6, 8, 9). Writes
//!   one chart each for parts delivered, collisions and MU, setups on the x axis by robot
//!   count, and marks the paper's MU (`--paper`) on the MU chart.
//! * `curves`: training `log.csv` files; per model, mean over seeds of each logged metric vs
//!   episodes with a std band (Fig. 5 and 7), and dashed lines where the curriculum stage
//!   changes (from log.csv's `setup` column, or `--schedule`).
//!
//! The model of a file is the first word of its `policy` column (eval) or the path
//! component naming a model (smappo, mappo, greedy, random); runs under a directory named
//! like a setup (experiment A's `runs/exp/A/<setup>/<model>/seed*`) get a column of panels
//! per setup.

use crate::plot_font::{draw_text, draw_text_up, text_height, text_width, Align};
use crate::stats::mean_std;
use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, Subcommand};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct PlotArgs {
    #[command(subcommand)]
    pub kind: PlotKind,
}

#[derive(Subcommand, Debug)]
pub enum PlotKind {
    /// Bar charts (parts, collisions, MU) per setup and model from eval results.csv files.
    Bars(BarsArgs),
    /// Training curves (reward, parts, MU vs episodes) per model from log.csv files.
    Curves(CurvesArgs),
    /// Parts vs contacts per robot-step, a panel per setup, a point per eval results.csv.
    Pareto(crate::plot_pareto::ParetoArgs),
}

#[derive(Args, Debug)]
pub struct BarsArgs {
    /// `tending eval` results.csv files: one per trained model (training seed), one per
    /// scripted baseline.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Output prefix: writes PREFIX_parts.png, PREFIX_collisions.png and PREFIX_mu.png.
    #[arg(long)]
    pub out: PathBuf,
    /// Chart title.
    #[arg(long, default_value = "")]
    pub title: String,
    /// The paper's MU to mark on the MU chart: CSV with columns experiment,setup,model,mu.
    #[arg(long, requires = "experiment")]
    pub paper: Option<PathBuf>,
    /// Which experiment's rows of --paper to use (A, B, C, D).
    #[arg(long)]
    pub experiment: Option<String>,
}

#[derive(Args, Debug)]
pub struct CurvesArgs {
    /// `tending train` log.csv files (one per training run; seeds of a model are averaged).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
    /// Chart title.
    #[arg(long, default_value = "")]
    pub title: String,
    /// Curriculum schedule SETUP:EPISODES,... (as `tending train --curriculum`) to mark the
    /// stage changes; default: from log.csv's `setup` column.
    #[arg(long)]
    pub schedule: Option<String>,
    /// Panels, top to bottom: any of reward, parts, collisions, mu.
    #[arg(long, default_value = "reward,parts,mu")]
    pub metrics: String,
    /// Moving average over this many updates (within a stage) before averaging seeds;
    /// 0: about a twentieth of the run.
    #[arg(long, default_value_t = 0)]
    pub smooth: usize,
}

pub fn run(a: PlotArgs) -> Result<()> {
    match a.kind {
        PlotKind::Bars(b) => run_bars(&b),
        PlotKind::Curves(c) => run_curves(&c),
        PlotKind::Pareto(p) => crate::plot_pareto::run(&p),
    }
}

// ---------------------------------------------------------------------------------------
// CSV reading

/// A comma-separated file with a header line (no quoting: the files tending writes).
#[derive(Debug)]
struct Csv {
    path: PathBuf,
    header: Vec<String>,
    /// (1-based line number, fields)
    rows: Vec<(usize, Vec<String>)>,
}

impl Csv {
    fn parse(path: &Path, text: &str) -> Result<Csv> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let Some((_, head)) = lines.next() else {
            bail!("{}: empty file (expected a CSV header)", path.display());
        };
        let header: Vec<String> = head.split(',').map(|s| s.trim().to_string()).collect();
        let mut rows = vec![];
        for (i, l) in lines {
            let f: Vec<String> = l.split(',').map(|s| s.trim().to_string()).collect();
            if f.len() != header.len() {
                bail!(
                    "{}:{}: {} fields, the header has {}",
                    path.display(),
                    i + 1,
                    f.len(),
                    header.len()
                );
            }
            rows.push((i + 1, f));
        }
        if rows.is_empty() {
            bail!("{}: no data rows", path.display());
        }
        Ok(Csv {
            path: path.to_path_buf(),
            header,
            rows,
        })
    }

    fn col(&self, name: &str) -> Result<usize> {
        self.opt_col(name).ok_or_else(|| {
            anyhow!(
                "{}: no column `{name}` (columns: {})",
                self.path.display(),
                self.header.join(",")
            )
        })
    }

    fn opt_col(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    fn num(&self, row: usize, col: usize) -> Result<f64> {
        let (line, f) = &self.rows[row];
        let v: f64 = f[col].parse().map_err(|_| {
            anyhow!(
                "{}:{line}: column `{}`: `{}` is not a number",
                self.path.display(),
                self.header[col],
                f[col]
            )
        })?;
        if !v.is_finite() {
            bail!(
                "{}:{line}: column `{}` is {v}",
                self.path.display(),
                self.header[col]
            );
        }
        Ok(v)
    }
}

// ---------------------------------------------------------------------------------------
// Names: models, setups

const KNOWN_MODELS: [&str; 4] = ["smappo", "mappo", "greedy", "random"];

/// The path component naming a model, nearest the file first.
fn model_from_path(p: &Path) -> Option<String> {
    p.components().rev().find_map(|c| {
        let s = c.as_os_str().to_str()?.to_ascii_lowercase();
        KNOWN_MODELS.contains(&s.as_str()).then_some(s)
    })
}

/// A directory named like a setup (experiment A keeps one per setup).
fn group_from_path(p: &Path) -> Option<String> {
    p.parent()?.components().rev().find_map(|c| {
        let s = c.as_os_str().to_str()?;
        setup_key(s).map(|_| s.to_string())
    })
}

/// (robots, machines, storages) of `N.M_K` or `N_M_K`.
fn setup_key(s: &str) -> Option<(u32, u32, u32)> {
    let v: Vec<u32> = s
        .split(['.', '_'])
        .map(|x| x.parse().ok())
        .collect::<Option<_>>()?;
    match v[..] {
        [n, m, k] => Some((n, m, k)),
        _ => None,
    }
}

/// Sorts setups the paper's way: by robots, then machines, then storages.
fn sort_setups(v: &mut [String]) {
    v.sort_by(|a, b| setup_key(a).cmp(&setup_key(b)).then_with(|| a.cmp(b)));
}

fn model_rank(m: &str) -> (usize, String) {
    let r = KNOWN_MODELS
        .iter()
        .position(|k| *k == m)
        .unwrap_or(KNOWN_MODELS.len());
    (r, m.to_string())
}

fn is_scripted(m: &str) -> bool {
    m == "greedy" || m == "random"
}

fn model_color(m: &str, others: &[String]) -> RGBColor {
    match m {
        "smappo" => RGBColor(31, 119, 180),
        "mappo" => RGBColor(230, 115, 0),
        "greedy" => RGBColor(95, 95, 95),
        "random" => RGBColor(175, 175, 175),
        _ => {
            let pal = [
                RGBColor(44, 160, 44),
                RGBColor(214, 39, 40),
                RGBColor(148, 103, 189),
                RGBColor(140, 86, 75),
            ];
            let i = others.iter().position(|o| o == m).unwrap_or(0);
            pal[i % pal.len()]
        }
    }
}

// ---------------------------------------------------------------------------------------
// Bars: evaluation results

const BAR_METRICS: [(&str, &str, &str); 3] = [
    ("parts", "parts delivered per episode", "parts delivered"),
    ("collisions", "collisions per episode", "collisions"),
    ("mu", "machine utilization MU", "MU"),
];

/// One `results.csv`: per setup, the mean over its rows (evaluation seeds) of
/// [parts delivered, collisions, MU].
#[derive(Debug, Clone)]
struct EvalRun {
    model: String,
    setups: BTreeMap<String, [f64; 3]>,
}

fn parse_eval(path: &Path, text: &str) -> Result<EvalRun> {
    let csv = Csv::parse(path, text)?;
    let pc = csv.col("policy")?;
    let sc = csv.col("setup")?;
    let cols = [
        csv.col("parts_delivered")?,
        csv.col("collisions")?,
        csv.col("mu")?,
    ];
    let mut model = None;
    let mut acc: BTreeMap<String, ([f64; 3], usize)> = BTreeMap::new();
    for i in 0..csv.rows.len() {
        let (line, f) = &csv.rows[i];
        let m = f[pc]
            .split_whitespace()
            .next()
            .map(str::to_ascii_lowercase)
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
        if setup_key(&f[sc]).is_none() {
            bail!("{}:{line}: setup `{}` is not N.M_K", path.display(), f[sc]);
        }
        let e = acc.entry(f[sc].clone()).or_insert(([0.0; 3], 0));
        for (k, &c) in cols.iter().enumerate() {
            e.0[k] += csv.num(i, c)?;
        }
        e.1 += 1;
    }
    Ok(EvalRun {
        model: model.expect("Csv::parse guarantees a row"),
        setups: acc
            .into_iter()
            .map(|(s, (sum, n))| (s, sum.map(|x| x / n as f64)))
            .collect(),
    })
}

/// Per setup and model: mean and std over runs (training seeds) of each metric.
#[derive(Debug, Clone)]
struct BarStat {
    setup: String,
    model: String,
    n: usize,
    mean: [f64; 3],
    std: [f64; 3],
}

fn aggregate_bars(runs: &[EvalRun]) -> Vec<BarStat> {
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
fn parse_paper(path: &Path, text: &str, exp: &str) -> Result<BTreeMap<(String, String), f64>> {
    let csv = Csv::parse(path, text)?;
    let (ec, sc, mc, vc) = (
        csv.col("experiment")?,
        csv.col("setup")?,
        csv.col("model")?,
        csv.col("mu")?,
    );
    let mut out = BTreeMap::new();
    for i in 0..csv.rows.len() {
        let f = &csv.rows[i].1;
        if f[ec] != exp {
            continue;
        }
        let (n, m, k) = setup_key(&f[sc]).ok_or_else(|| {
            anyhow!(
                "{}:{}: setup `{}` is not N.M_K",
                path.display(),
                csv.rows[i].0,
                f[sc]
            )
        })?;
        out.insert(
            (format!("{n}.{m}_{k}"), f[mc].to_ascii_lowercase()),
            csv.num(i, vc)?,
        );
    }
    Ok(out)
}

fn check_inputs(files: &[PathBuf]) -> Result<()> {
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

fn run_bars(a: &BarsArgs) -> Result<()> {
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

// ---------------------------------------------------------------------------------------
// Curves: training logs

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Metric {
    Reward,
    Parts,
    Collisions,
    Mu,
}

impl Metric {
    fn parse(s: &str) -> Result<Metric> {
        Ok(match s.trim() {
            "reward" | "team_reward" => Metric::Reward,
            "parts" | "parts_delivered" => Metric::Parts,
            "collisions" => Metric::Collisions,
            "mu" | "MU" => Metric::Mu,
            o => bail!("unknown metric `{o}`: expected reward, parts, collisions or mu"),
        })
    }
    fn column(self) -> &'static str {
        match self {
            Metric::Reward => "team_reward",
            Metric::Parts => "parts_delivered",
            Metric::Collisions => "collisions",
            Metric::Mu => "mu",
        }
    }
    fn title(self) -> &'static str {
        match self {
            Metric::Reward => "team reward",
            Metric::Parts => "parts delivered",
            Metric::Collisions => "collisions",
            Metric::Mu => "MU",
        }
    }
    fn index(self) -> usize {
        self as usize
    }
}

/// One training run's log.
#[derive(Debug, Clone)]
struct LogRun {
    path: PathBuf,
    model: String,
    group: Option<String>,
    episodes: Vec<f64>,
    setups: Option<Vec<String>>,
    /// Per metric (Metric::index), the column if the log has it.
    values: [Option<Vec<f64>>; 4],
}

fn parse_log(path: &Path, text: &str) -> Result<LogRun> {
    let csv = Csv::parse(path, text)?;
    let ec = csv.col("episodes")?;
    csv.col("team_reward")?;
    let n = csv.rows.len();
    let episodes = (0..n).map(|i| csv.num(i, ec)).collect::<Result<Vec<_>>>()?;
    if let Some(i) = (1..n).find(|&i| episodes[i] <= episodes[i - 1]) {
        bail!(
            "{}:{}: episodes {} do not increase (previous row {})",
            path.display(),
            csv.rows[i].0,
            episodes[i],
            episodes[i - 1]
        );
    }
    let setups = csv
        .opt_col("setup")
        .map(|c| csv.rows.iter().map(|(_, f)| f[c].clone()).collect());
    let mut values: [Option<Vec<f64>>; 4] = Default::default();
    for m in [
        Metric::Reward,
        Metric::Parts,
        Metric::Collisions,
        Metric::Mu,
    ] {
        if let Some(c) = csv.opt_col(m.column()) {
            values[m.index()] = Some((0..n).map(|i| csv.num(i, c)).collect::<Result<_>>()?);
        }
    }
    let model = model_from_path(path).unwrap_or_else(|| {
        path.parent()
            .and_then(|p| p.file_name())
            .and_then(|f| f.to_str())
            .unwrap_or("run")
            .to_string()
    });
    Ok(LogRun {
        path: path.to_path_buf(),
        model,
        group: group_from_path(path),
        episodes,
        setups,
        values,
    })
}

/// Stage starts (episodes, setup) of a schedule `SETUP:EPISODES,...`.
fn parse_schedule(s: &str) -> Result<Vec<(f64, String)>> {
    let mut out = vec![];
    let mut at = 0.0;
    for part in s.split(',').filter(|p| !p.trim().is_empty()) {
        let (setup, eps) = part
            .trim()
            .split_once(':')
            .ok_or_else(|| anyhow!("--schedule: `{part}` is not SETUP:EPISODES"))?;
        if setup_key(setup).is_none() {
            bail!("--schedule: setup `{setup}` is not N.M_K");
        }
        let e: f64 = eps
            .parse()
            .map_err(|_| anyhow!("--schedule: `{eps}` is not a number of episodes"))?;
        out.push((at, setup.to_string()));
        at += e;
    }
    if out.is_empty() {
        bail!("--schedule is empty");
    }
    Ok(out)
}

/// Stage starts read from a log's setup column: a stage starts where the previous update
/// ended (log rows carry the episode count at the end of their update).
fn stage_marks(run: &LogRun) -> Vec<(f64, String)> {
    let Some(setups) = &run.setups else {
        return vec![];
    };
    let mut out = vec![];
    for i in 0..setups.len() {
        if i == 0 {
            out.push((0.0, setups[0].clone()));
        } else if setups[i] != setups[i - 1] {
            out.push((run.episodes[i - 1], setups[i].clone()));
        }
    }
    out
}

/// Index of each point's stage (the last stage start before its end-of-update episode).
fn stage_ids(episodes: &[f64], marks: &[(f64, String)]) -> Vec<usize> {
    episodes
        .iter()
        .map(|&e| {
            marks
                .iter()
                .filter(|(s, _)| *s < e)
                .count()
                .saturating_sub(1)
        })
        .collect()
}

/// Trailing moving average of width `w` that restarts at every stage change.
fn smooth_within_stages(xs: &[f64], stage: &[usize], w: usize) -> Vec<f64> {
    let w = w.max(1);
    let mut start = 0;
    (0..xs.len())
        .map(|i| {
            if i > 0 && stage[i] != stage[i - 1] {
                start = i;
            }
            let lo = start.max((i + 1).saturating_sub(w));
            let s = &xs[lo..=i];
            s.iter().sum::<f64>() / s.len() as f64
        })
        .collect()
}

/// A model's curve: per x (episodes), mean, std and number of runs.
type Curve = Vec<(f64, f64, f64, usize)>;

fn aggregate_curves(series: &[(Vec<f64>, Vec<f64>)]) -> Curve {
    let mut by: BTreeMap<i64, (f64, Vec<f64>)> = BTreeMap::new();
    for (xs, ys) in series {
        for (x, y) in xs.iter().zip(ys) {
            by.entry((x * 1000.0).round() as i64)
                .or_insert((*x, vec![]))
                .1
                .push(*y);
        }
    }
    by.into_values()
        .map(|(x, ys)| {
            let (m, s) = mean_std(&ys);
            (x, m, s, ys.len())
        })
        .collect()
}

struct CurveGroup {
    name: Option<String>,
    marks: Vec<(f64, String)>,
    /// model -> (runs, per metric curve)
    models: Vec<(String, usize, Vec<Curve>)>,
    x_max: f64,
}

fn build_groups(
    runs: &[LogRun],
    metrics: &[Metric],
    schedule: &Option<Vec<(f64, String)>>,
    smooth: usize,
) -> Vec<CurveGroup> {
    let names: BTreeSet<Option<String>> = runs.iter().map(|r| r.group.clone()).collect();
    let mut names: Vec<Option<String>> = names.into_iter().collect();
    names.sort_by(|a, b| {
        a.as_deref()
            .and_then(setup_key)
            .cmp(&b.as_deref().and_then(setup_key))
    });
    names
        .into_iter()
        .map(|name| {
            let rs: Vec<&LogRun> = runs.iter().filter(|r| r.group == name).collect();
            let marks: Vec<(f64, String)> = match schedule {
                Some(s) => s.clone(),
                None => {
                    let set: BTreeSet<(i64, String)> = rs
                        .iter()
                        .flat_map(|r| stage_marks(r))
                        .map(|(x, s)| ((x * 1000.0).round() as i64, s))
                        .collect();
                    set.into_iter()
                        .map(|(x, s)| (x as f64 / 1000.0, s))
                        .collect()
                }
            };
            let mut models: Vec<String> = rs.iter().map(|r| r.model.clone()).collect();
            models.sort_by_key(|m| model_rank(m));
            models.dedup();
            let x_max = rs
                .iter()
                .filter_map(|r| r.episodes.last().copied())
                .fold(1.0, f64::max);
            let models = models
                .into_iter()
                .map(|m| {
                    let mine: Vec<&&LogRun> = rs.iter().filter(|r| r.model == m).collect();
                    let curves = metrics
                        .iter()
                        .map(|metric| {
                            let series: Vec<(Vec<f64>, Vec<f64>)> = mine
                                .iter()
                                .filter_map(|r| {
                                    let ys = r.values[metric.index()].as_ref()?;
                                    let own = stage_marks(r);
                                    let st = stage_ids(
                                        &r.episodes,
                                        if own.is_empty() { &marks } else { &own },
                                    );
                                    Some((
                                        r.episodes.clone(),
                                        smooth_within_stages(ys, &st, smooth),
                                    ))
                                })
                                .collect();
                            aggregate_curves(&series)
                        })
                        .collect();
                    (m, mine.len(), curves)
                })
                .collect();
            CurveGroup {
                name,
                marks,
                models,
                x_max,
            }
        })
        .collect()
}

fn run_curves(a: &CurvesArgs) -> Result<()> {
    check_inputs(&a.files)?;
    let metrics: Vec<Metric> = a
        .metrics
        .split(',')
        .map(Metric::parse)
        .collect::<Result<_>>()?;
    if metrics.is_empty() {
        bail!("--metrics: name at least one of reward, parts, collisions, mu");
    }
    let schedule = a.schedule.as_deref().map(parse_schedule).transpose()?;
    let mut runs = vec![];
    for f in &a.files {
        let text =
            std::fs::read_to_string(f).with_context(|| format!("{}: cannot read", f.display()))?;
        runs.push(parse_log(f, &text)?);
    }
    // A panel only for metrics every log has.
    let metrics: Vec<Metric> = metrics
        .into_iter()
        .filter(|m| {
            let missing: Vec<String> = runs
                .iter()
                .filter(|r| r.values[m.index()].is_none())
                .map(|r| r.path.display().to_string())
                .collect();
            if !missing.is_empty() {
                eprintln!(
                    "note: no `{}` column in {}: panel left out",
                    m.column(),
                    missing.join(", ")
                );
            }
            missing.is_empty()
        })
        .collect();
    let longest = runs.iter().map(|r| r.episodes.len()).max().unwrap_or(1);
    let smooth = if a.smooth > 0 {
        a.smooth
    } else {
        (longest / 20).max(1)
    };
    let groups = build_groups(&runs, &metrics, &schedule, smooth);
    let how = if smooth > 1 {
        format!(", moving average of {smooth} updates")
    } else {
        String::new()
    };
    let subtitle = format!("line: mean over training seeds{how}; band: std over seeds");
    draw_curves(&groups, &metrics, &a.title, &subtitle, &a.out)?;
    eprintln!("wrote {}", a.out.display());
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Drawing

const FS: i32 = 2; // text scale of labels
const GRID: RGBColor = RGBColor(225, 225, 225);
const INK: RGBColor = RGBColor(30, 30, 30);
const SOFT: RGBColor = RGBColor(100, 100, 100);

struct Canvas<'a> {
    area: DrawingArea<BitMapBackend<'a>, Shift>,
    path: &'a Path,
}

impl<'a> Canvas<'a> {
    fn new(path: &'a Path, w: i32, h: i32) -> Result<Canvas<'a>> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: cannot create", dir.display()))?;
        }
        let area = BitMapBackend::new(path, (w as u32, h as u32)).into_drawing_area();
        let c = Canvas { area, path };
        c.area.fill(&WHITE).map_err(|e| c.err(e))?;
        Ok(c)
    }
    fn err(&self, e: impl std::fmt::Debug) -> anyhow::Error {
        anyhow!("plot {}: {e:?}", self.path.display())
    }
    fn line(&self, pts: Vec<(i32, i32)>, color: RGBColor, width: u32) -> Result<()> {
        self.area
            .draw(&PathElement::new(pts, color.stroke_width(width)))
            .map_err(|e| self.err(e))
    }
    fn dashed_vline(&self, x: i32, y0: i32, y1: i32, color: RGBColor) -> Result<()> {
        let mut y = y0;
        while y < y1 {
            self.line(vec![(x, y), (x, (y + 7).min(y1))], color, 2)?;
            y += 12;
        }
        Ok(())
    }
    fn rect(&self, a: (i32, i32), b: (i32, i32), color: RGBColor) -> Result<()> {
        self.area
            .draw(&Rectangle::new([a, b], color.filled()))
            .map_err(|e| self.err(e))
    }
    fn frame(&self, a: (i32, i32), b: (i32, i32), color: RGBColor) -> Result<()> {
        self.area
            .draw(&Rectangle::new([a, b], color.stroke_width(1)))
            .map_err(|e| self.err(e))
    }
    fn band(&self, pts: Vec<(i32, i32)>, color: RGBColor) -> Result<()> {
        self.area
            .draw(&Polygon::new(pts, color.mix(0.22).filled()))
            .map_err(|e| self.err(e))
    }
    fn diamond(&self, (x, y): (i32, i32), r: i32, color: RGBColor) -> Result<()> {
        let pts = vec![(x, y - r), (x + r, y), (x, y + r), (x - r, y)];
        self.area
            .draw(&Polygon::new(pts.clone(), color.filled()))
            .map_err(|e| self.err(e))?;
        let mut closed = pts;
        closed.push((x, y - r));
        self.line(closed, WHITE, 1)
    }
    fn text(&self, s: &str, at: (i32, i32), align: Align, scale: i32, color: RGBColor) {
        draw_text(&self.area, s, at, align, scale, color);
    }
    fn text_up(&self, s: &str, at: (i32, i32), scale: i32, color: RGBColor) {
        draw_text_up(&self.area, s, at, scale, color);
    }
    fn finish(self) -> Result<()> {
        self.area.present().map_err(|e| self.err(e))
    }
}

/// A plot rectangle in pixels and the data ranges it shows.
#[derive(Debug, Clone, Copy)]
struct Frame {
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
    xlo: f64,
    xhi: f64,
    ylo: f64,
    yhi: f64,
}

impl Frame {
    fn px(&self, x: f64) -> i32 {
        let t = (x - self.xlo) / (self.xhi - self.xlo).max(1e-12);
        self.x0 + (t * (self.x1 - self.x0) as f64).round() as i32
    }
    fn py(&self, y: f64) -> i32 {
        let t = (y - self.ylo) / (self.yhi - self.ylo).max(1e-12);
        self.y1 - (t * (self.y1 - self.y0) as f64).round() as i32
    }
}

/// A 1-2-5 step giving about `target` intervals over `range`.
fn nice_step(range: f64, target: usize) -> f64 {
    let raw = (range / target.max(1) as f64).max(1e-9);
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let n = if f <= 1.0 {
        1.0
    } else if f <= 2.0 {
        2.0
    } else if f <= 5.0 {
        5.0
    } else {
        10.0
    };
    n * mag
}

/// Tick values from `lo` to `hi` (inclusive) with `step`.
fn ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let mut v = (lo / step).ceil() * step;
    let mut out = vec![];
    while v <= hi + step * 1e-6 {
        out.push(if v.abs() < step * 1e-6 { 0.0 } else { v });
        v += step;
    }
    out
}

fn fmt_tick(v: f64, step: f64) -> String {
    let d = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil().max(0.0) as usize
    };
    format!("{v:.d$}")
}

/// Range rounded outwards to ticks: (lo, hi, step).
fn nice_range(lo: f64, hi: f64, target: usize) -> (f64, f64, f64) {
    let (lo, hi) = if hi - lo < 1e-9 {
        (
            lo - 0.5_f64.max(lo.abs() * 0.1),
            hi + 0.5_f64.max(hi.abs() * 0.1),
        )
    } else {
        (lo, hi)
    };
    let step = nice_step(hi - lo, target);
    ((lo / step).floor() * step, (hi / step).ceil() * step, step)
}

/// Horizontal grid, y tick labels and the frame.
fn draw_y_axis(c: &Canvas, f: &Frame, step: f64) -> Result<()> {
    for v in ticks(f.ylo, f.yhi, step) {
        let y = f.py(v);
        c.line(vec![(f.x0, y), (f.x1, y)], GRID, 1)?;
        c.line(vec![(f.x0 - 5, y), (f.x0, y)], INK, 1)?;
        c.text(
            &fmt_tick(v, step),
            (f.x0 - 9, y - text_height(FS) / 2),
            Align::Right,
            FS,
            INK,
        );
    }
    Ok(())
}

/// A row of legend entries (colour swatch + label) that wraps at `max_x`; returns the y
/// below it.
fn draw_legend(
    c: &Canvas,
    entries: &[(RGBColor, String, LegendMark)],
    x0: i32,
    y0: i32,
    max_x: i32,
) -> Result<i32> {
    let row_h = 24;
    let (mut x, mut y) = (x0, y0);
    for (color, label, mark) in entries {
        let w = 26 + text_width(label, FS) + 24;
        if x + w > max_x && x > x0 {
            x = x0;
            y += row_h;
        }
        let cy = y + text_height(FS) / 2;
        match mark {
            LegendMark::Box => c.rect((x, cy - 7), (x + 16, cy + 7), *color)?,
            LegendMark::Line => c.line(vec![(x, cy), (x + 18, cy)], *color, 3)?,
            LegendMark::Diamond => c.diamond((x + 8, cy), 7, *color)?,
            LegendMark::Dashed => c.dashed_vline(x + 8, cy - 9, cy + 9, *color)?,
        }
        c.text(label, (x + 26, y), Align::Left, FS, INK);
        x += w;
    }
    Ok(y + row_h)
}

#[derive(Debug, Clone, Copy)]
enum LegendMark {
    Box,
    Line,
    Diamond,
    Dashed,
}

fn model_label(m: &str, n: usize) -> String {
    if is_scripted(m) {
        format!("{m} (scripted)")
    } else if n == 1 {
        format!("{m} (1 seed)")
    } else {
        format!("{m} ({n} seeds)")
    }
}

fn draw_bars(
    stats: &[BarStat],
    k: usize,
    title: &str,
    ylabel: &str,
    paper: Option<&BTreeMap<(String, String), f64>>,
    path: &Path,
) -> Result<()> {
    let mut setups: Vec<String> = stats.iter().map(|s| s.setup.clone()).collect();
    setups.dedup();
    sort_setups(&mut setups);
    setups.dedup();
    let mut models: Vec<String> = stats.iter().map(|s| s.model.clone()).collect();
    models.sort_by_key(|m| model_rank(m));
    models.dedup();
    let others: Vec<String> = models
        .iter()
        .filter(|m| !KNOWN_MODELS.contains(&m.as_str()))
        .cloned()
        .collect();
    let nm = models.len().max(1) as i32;
    let bar_w = 26;
    let group_w = (nm * bar_w + 40).max(110);
    let left = 112;
    let w = (left + setups.len() as i32 * group_w + 30)
        .max(900)
        .max(text_width(title, 3) + 40);
    let plot_w = w - left - 30;
    let group_w = plot_w / setups.len().max(1) as i32;
    let paper_pts: Vec<(usize, usize, f64)> = paper
        .map(|p| {
            setups
                .iter()
                .enumerate()
                .flat_map(|(si, s)| {
                    models.iter().enumerate().filter_map(move |(mi, m)| {
                        p.get(&(s.clone(), m.clone())).map(|v| (si, mi, *v))
                    })
                })
                .collect()
        })
        .unwrap_or_default();

    let mut hi = stats
        .iter()
        .map(|s| s.mean[k] + s.std[k])
        .fold(0.0, f64::max);
    hi = paper_pts.iter().map(|p| p.2).fold(hi, f64::max);
    let (_, mut yhi, step) = nice_range(0.0, hi * 1.04, 6);
    if k == 2 && yhi > 1.0 && hi <= 1.0 {
        yhi = 1.0;
    }

    // Legend entries first: their rows decide where the plot starts.
    let legend_n = |m: &String| {
        stats
            .iter()
            .filter(|s| &s.model == m)
            .map(|s| s.n)
            .max()
            .unwrap_or(0)
    };
    let mut entries: Vec<(RGBColor, String, LegendMark)> = models
        .iter()
        .map(|m| {
            (
                model_color(m, &others),
                model_label(m, legend_n(m)),
                LegendMark::Box,
            )
        })
        .collect();
    if !paper_pts.is_empty() {
        entries.push((INK, "paper, full budget".into(), LegendMark::Diamond));
    }
    let h_guess = 560;
    let c = Canvas::new(path, w, h_guess)?;
    c.text(title, (w / 2, 14), Align::Center, 3, INK);
    c.text(
        "bar: mean over training seeds;  error bar: std over seeds",
        (w / 2, 44),
        Align::Center,
        FS,
        SOFT,
    );
    let top = draw_legend(&c, &entries, left, 72, w - 20)? + 12;
    let f = Frame {
        x0: left,
        y0: top,
        x1: left + plot_w,
        y1: h_guess - 80,
        xlo: 0.0,
        xhi: setups.len() as f64,
        ylo: 0.0,
        yhi,
    };
    draw_y_axis(&c, &f, step)?;
    c.text_up(ylabel, (14, (f.y0 + f.y1) / 2), FS, INK);

    // Bars as wide as the groups allow, up to 44 px.
    let inner = (nm * 44)
        .min(group_w * 3 / 4)
        .max((nm * bar_w).min(group_w - 16));
    let bw = inner / nm;
    let bar_x =
        |si: usize, mi: usize| f.x0 + si as i32 * group_w + (group_w - inner) / 2 + mi as i32 * bw;
    for (si, s) in setups.iter().enumerate() {
        let gx = f.x0 + si as i32 * group_w;
        if si > 0 {
            c.line(vec![(gx, f.y1), (gx, f.y1 + 6)], INK, 1)?;
        }
        c.text(s, (gx + group_w / 2, f.y1 + 12), Align::Center, FS, INK);
        for (mi, m) in models.iter().enumerate() {
            let Some(st) = stats.iter().find(|t| &t.setup == s && &t.model == m) else {
                continue;
            };
            let x = bar_x(si, mi);
            let color = model_color(m, &others);
            let y = f.py(st.mean[k]);
            if y < f.y1 {
                c.rect((x + 1, y), (x + bw - 2, f.y1), color)?;
            }
            if st.n != legend_n(m) {
                // Fewer runs here than the legend says (an experiment still running).
                let top = f.py(st.mean[k] + st.std[k]).min(y);
                let label = format!("n={}", st.n);
                c.text(&label, (x + bw / 2 - 1, top - 20), Align::Center, FS, INK);
            }
            if st.n > 1 && st.std[k] > 0.0 {
                let cx = x + bw / 2 - 1;
                let (ylo, yhi) = (
                    f.py((st.mean[k] - st.std[k]).max(0.0)),
                    f.py(st.mean[k] + st.std[k]),
                );
                c.line(vec![(cx, ylo), (cx, yhi)], INK, 2)?;
                c.line(vec![(cx - 4, yhi), (cx + 4, yhi)], INK, 2)?;
                c.line(vec![(cx - 4, ylo), (cx + 4, ylo)], INK, 2)?;
            }
        }
    }
    for &(si, mi, v) in &paper_pts {
        let x = bar_x(si, mi) + bw / 2 - 1;
        c.diamond((x, f.py(v)), 7, INK)?;
    }
    c.line(vec![(f.x0, f.y1), (f.x1, f.y1)], INK, 1)?;
    c.frame((f.x0, f.y0), (f.x1, f.y1), INK)?;
    c.text(
        "setup (robots.machines_storages)",
        ((f.x0 + f.x1) / 2, f.y1 + 42),
        Align::Center,
        FS,
        INK,
    );
    c.finish()
}

fn draw_curves(
    groups: &[CurveGroup],
    metrics: &[Metric],
    title: &str,
    subtitle: &str,
    path: &Path,
) -> Result<()> {
    if groups.is_empty() || metrics.is_empty() {
        bail!("{}: nothing to plot", path.display());
    }
    // Groups (setups of experiment A) side by side, at most three to a row.
    let ncols = groups.len().min(3) as i32;
    let grid_rows = (groups.len() as i32 + ncols - 1) / ncols;
    let panel_w = if ncols == 1 { 880 } else { 460 };
    let panel_h = 210;
    let left = 96;
    let col_w = left + panel_w + 24;
    let w = (ncols * col_w + 10).max(900).max(text_width(title, 3) + 40);

    // Stage labels above the first panel, in as many rows as keep them apart.
    let mut label_rows: Vec<Vec<(i32, usize)>> = vec![]; // per group: (x, row)
    let mut n_label_rows = 0;
    for (gi, g) in groups.iter().enumerate() {
        let x0 = (gi as i32 % ncols) * col_w + left;
        let f = Frame {
            x0,
            y0: 0,
            x1: x0 + panel_w,
            y1: 1,
            xlo: 0.0,
            xhi: g.x_max,
            ylo: 0.0,
            yhi: 1.0,
        };
        let mut ends: Vec<i32> = vec![];
        let mut placed = vec![];
        if g.marks.len() > 1 {
            for (x, s) in &g.marks {
                let px = f.px(*x) + 4;
                let wl = text_width(s, FS);
                let row = match ends.iter().position(|&e| e + 10 <= px) {
                    Some(r) => r,
                    None => {
                        ends.push(i32::MIN);
                        ends.len() - 1
                    }
                };
                ends[row] = px + wl;
                placed.push((px, row));
            }
        }
        n_label_rows = n_label_rows.max(ends.len());
        label_rows.push(placed);
    }

    // Legend: models over all groups.
    let mut models: Vec<(String, usize)> = vec![];
    for g in groups {
        for (m, n, _) in &g.models {
            match models.iter_mut().find(|(o, _)| o == m) {
                Some(e) => e.1 = e.1.max(*n),
                None => models.push((m.clone(), *n)),
            }
        }
    }
    models.sort_by_key(|(m, _)| model_rank(m));
    let others: Vec<String> = models
        .iter()
        .map(|(m, _)| m.clone())
        .filter(|m| !KNOWN_MODELS.contains(&m.as_str()))
        .collect();
    let mut entries: Vec<(RGBColor, String, LegendMark)> = models
        .iter()
        .map(|(m, n)| {
            (
                model_color(m, &others),
                model_label(m, *n),
                LegendMark::Line,
            )
        })
        .collect();
    if n_label_rows > 0 {
        entries.push((SOFT, "curriculum stage starts".into(), LegendMark::Dashed));
    }

    // Height: title, subtitle, legend (measured on a scratch pass), headers, panels.
    let legend_rows = {
        let mut rows = 1;
        let mut x = left;
        for (_, l, _) in &entries {
            let ew = 26 + text_width(l, FS) + 24;
            if x + ew > w - 20 && x > left {
                rows += 1;
                x = left;
            }
            x += ew;
        }
        rows
    };
    let header_h = if groups.iter().any(|g| g.name.is_some()) {
        30
    } else {
        0
    };
    let strip_h = n_label_rows as i32 * 22;
    let base = 72 + legend_rows * 24 + 8;
    let row_h = panel_h + 40;
    let block_h = header_h + strip_h + (metrics.len() as i32 - 1) * row_h + panel_h + 64;
    let h = base + grid_rows * block_h;

    let c = Canvas::new(path, w, h)?;
    c.text(title, (w / 2, 14), Align::Center, 3, INK);
    c.text(subtitle, (w / 2, 44), Align::Center, FS, SOFT);
    draw_legend(&c, &entries, left, 72, w - 20)?;

    for (gi, g) in groups.iter().enumerate() {
        let x0 = (gi as i32 % ncols) * col_w + left;
        let block = base + (gi as i32 / ncols) * block_h;
        let top = block + header_h + strip_h;
        let bottom = top + (metrics.len() as i32 - 1) * row_h + panel_h;
        if let Some(name) = &g.name {
            // Seeds per model where they differ from the legend's (a run still going).
            let fewer: Vec<String> = g
                .models
                .iter()
                .filter(|(m, n, _)| models.iter().any(|(o, on)| o == m && on != n))
                .map(|(m, n, _)| format!("{m} {n}"))
                .collect();
            let head = if fewer.is_empty() {
                format!("setup {name}")
            } else {
                format!("setup {name} (seeds: {})", fewer.join(", "))
            };
            c.text(&head, (x0 + panel_w / 2, block + 2), Align::Center, FS, INK);
        }
        for (pi, metric) in metrics.iter().enumerate() {
            let y0 = top + pi as i32 * row_h;
            let mut lo = f64::INFINITY;
            let mut hi = f64::NEG_INFINITY;
            for (_, _, curves) in &g.models {
                for &(_, m, s, _) in &curves[pi] {
                    lo = lo.min(m - s);
                    hi = hi.max(m + s);
                }
            }
            if !lo.is_finite() {
                (lo, hi) = (0.0, 1.0);
            }
            if *metric != Metric::Reward {
                lo = lo.min(0.0);
            }
            let (ylo, mut yhi, step) = nice_range(lo, hi, 5);
            let ylo = if *metric != Metric::Reward { 0.0 } else { ylo };
            if *metric == Metric::Mu && yhi > 1.0 && hi <= 1.0 {
                yhi = 1.0;
            }
            let f = Frame {
                x0,
                y0,
                x1: x0 + panel_w,
                y1: y0 + panel_h,
                xlo: 0.0,
                xhi: g.x_max,
                ylo,
                yhi,
            };
            c.text_up(metric.title(), (x0 - left + 12, (f.y0 + f.y1) / 2), FS, INK);
            draw_y_axis(&c, &f, step)?;
            let (_, _, xstep) = nice_range(0.0, g.x_max, if ncols == 1 { 10 } else { 5 });
            for v in ticks(0.0, g.x_max, xstep) {
                let x = f.px(v);
                c.line(vec![(x, f.y1), (x, f.y1 + 5)], INK, 1)?;
                c.text(&fmt_tick(v, xstep), (x, f.y1 + 9), Align::Center, FS, INK);
            }
            if g.marks.len() > 1 {
                for (x, _) in &g.marks {
                    if *x > 0.0 {
                        c.dashed_vline(f.px(*x), f.y0, f.y1, SOFT)?;
                    }
                }
            }
            for (m, _, curves) in &g.models {
                let color = model_color(m, &others);
                let cv = &curves[pi];
                if cv.iter().any(|p| p.3 > 1) && cv.len() > 1 {
                    let mut pts: Vec<(i32, i32)> =
                        cv.iter().map(|p| (f.px(p.0), f.py(p.1 + p.2))).collect();
                    pts.extend(cv.iter().rev().map(|p| (f.px(p.0), f.py(p.1 - p.2))));
                    c.band(pts, color)?;
                }
                if cv.len() == 1 {
                    c.diamond((f.px(cv[0].0), f.py(cv[0].1)), 4, color)?;
                } else {
                    c.line(
                        cv.iter().map(|p| (f.px(p.0), f.py(p.1))).collect(),
                        color,
                        2,
                    )?;
                }
            }
            c.frame((f.x0, f.y0), (f.x1, f.y1), INK)?;
            if pi == 0 {
                // Stage labels in the strip above the first panel, joined to their line.
                for (&(px, row), (x, s)) in label_rows[gi].iter().zip(&g.marks) {
                    let ly = top - strip_h + row as i32 * 22 + 2;
                    c.text(s, (px, ly), Align::Left, FS, SOFT);
                    let lx = f.px(*x);
                    c.line(vec![(lx, ly - 2), (lx, top)], SOFT, 1)?;
                }
            }
        }
        let yb = bottom + 32;
        c.text(
            if ncols == 1 {
                "episodes (metrics per episode, one point per update)"
            } else {
                "episodes"
            },
            (x0 + panel_w / 2, yb),
            Align::Center,
            FS,
            INK,
        );
    }
    c.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    const EVAL_S0: &str = "policy,setup,seed,episodes,parts_delivered,collisions,mu,team_reward\n\
        smappo (policy.safetensors),6.4_2,0,20,10.0,500.0,0.40,-100\n\
        smappo (policy.safetensors),6.4_2,1,20,12.0,520.0,0.44,-90\n\
        smappo (policy.safetensors),12.8_4,0,20,30.0,1800.0,0.45,-200\n";
    const EVAL_S1: &str = "policy,setup,seed,episodes,parts_delivered,collisions,mu,team_reward\n\
        smappo (policy.safetensors),12.8_4,0,20,20.0,2000.0,0.35,-210\n\
        smappo (policy.safetensors),6.4_2,0,20,15.0,600.0,0.50,-80\n";
    const EVAL_GREEDY: &str =
        "policy,setup,seed,episodes,parts_delivered,collisions,mu,team_reward\n\
        greedy,2.2_2,0,20,4.0,90.0,0.3,-20\n\
        greedy,12.8_4,0,20,25.0,1500.0,0.41,-150\n";

    fn p(s: &str) -> PathBuf {
        PathBuf::from(s)
    }

    #[test]
    fn eval_rows_of_a_setup_are_averaged_over_eval_seeds() {
        let r = parse_eval(&p("runs/exp/C/smappo/seed0/eval/results.csv"), EVAL_S0).unwrap();
        assert_eq!(r.model, "smappo");
        let v = r.setups["6.4_2"];
        assert!((v[0] - 11.0).abs() < 1e-12 && (v[1] - 510.0).abs() < 1e-12);
        assert!((v[2] - 0.42).abs() < 1e-12);
        assert_eq!(r.setups.len(), 2);
    }

    #[test]
    fn bars_are_mean_and_std_over_training_seeds_in_paper_order() {
        let runs = vec![
            parse_eval(&p("a/smappo/seed0/results.csv"), EVAL_S0).unwrap(),
            parse_eval(&p("a/smappo/seed1/results.csv"), EVAL_S1).unwrap(),
            parse_eval(&p("a/greedy/eval/results.csv"), EVAL_GREEDY).unwrap(),
        ];
        let st = aggregate_bars(&runs);
        let order: Vec<(&str, &str)> = st
            .iter()
            .map(|s| (s.setup.as_str(), s.model.as_str()))
            .collect();
        assert_eq!(
            order,
            [
                ("2.2_2", "greedy"),
                ("6.4_2", "smappo"),
                ("12.8_4", "smappo"),
                ("12.8_4", "greedy")
            ]
        );
        let s = &st[1]; // 6.4_2 smappo: seed means 11 and 15
        assert_eq!(s.n, 2);
        assert!((s.mean[0] - 13.0).abs() < 1e-12 && (s.std[0] - 2.0).abs() < 1e-12);
        assert!((s.mean[2] - 0.46).abs() < 1e-12 && (s.std[2] - 0.04).abs() < 1e-12);
        assert_eq!(st[3].n, 1);
        assert_eq!(st[3].std, [0.0; 3]);
    }

    #[test]
    fn malformed_csvs_name_the_file_and_line() {
        let f = p("runs/x/eval/results.csv");
        let e = parse_eval(&f, "").unwrap_err().to_string();
        assert!(
            e.contains("runs/x/eval/results.csv") && e.contains("empty"),
            "{e}"
        );
        let e = parse_eval(&f, "policy,setup,parts_delivered,collisions\n").unwrap_err();
        assert!(e.to_string().contains("no data rows"), "{e}");
        let e = parse_eval(&f, "policy,setup,parts_delivered,collisions\ng,6.4_2,1,2\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("runs/x/eval/results.csv") && e.contains("`mu`"),
            "{e}"
        );
        let e = parse_eval(
            &f,
            "policy,setup,parts_delivered,collisions,mu\ng,6.4_2,1,2,0.1\ng,6.4_2,x,2,0.1\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("results.csv:3") && e.contains("parts_delivered"),
            "{e}"
        );
        let e = parse_eval(
            &f,
            "policy,setup,parts_delivered,collisions,mu\ng,6.4_2,1,2\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("results.csv:2") && e.contains("4 fields"), "{e}");
        let e = parse_log(&p("r/log.csv"), "episodes,team_reward\n8,1\n8,2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("r/log.csv:3") && e.contains("increase"), "{e}");
        let missing = BarsArgs {
            files: vec![p("/nonexistent/results.csv")],
            out: std::env::temp_dir().join("never"),
            title: String::new(),
            paper: None,
            experiment: None,
        };
        let e = run_bars(&missing).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/results.csv"), "{e}");
    }

    #[test]
    fn setups_sort_by_robot_count_and_names_come_from_paths() {
        let mut v: Vec<String> = ["12.8_4", "2.2_2", "6.4_2", "4.2_2", "100.16_2", "42_28_14"]
            .map(String::from)
            .to_vec();
        sort_setups(&mut v);
        assert_eq!(
            v,
            ["2.2_2", "4.2_2", "6.4_2", "12.8_4", "42_28_14", "100.16_2"]
        );
        let a = p("runs/exp/A/12.8_4/mappo/seed2/log.csv");
        assert_eq!(model_from_path(&a).as_deref(), Some("mappo"));
        assert_eq!(group_from_path(&a).as_deref(), Some("12.8_4"));
        assert_eq!(group_from_path(&p("runs/exp/C/smappo/seed0/log.csv")), None);
        let paper =
            "experiment,setup,model,mu,std\nC,2_2_2,SMAPPO,0.5,0.13\nA,6.4_2,smappo,0.74,0.01\n";
        let m = parse_paper(&p("paper.csv"), paper, "C").unwrap();
        assert_eq!(m.len(), 1);
        assert_eq!(m[&("2.2_2".to_string(), "smappo".to_string())], 0.5);
    }

    fn log(setups: &[&str], rewards: &[f64]) -> String {
        let mut s = String::from("update,episodes,setup,team_reward,parts_delivered,mu\n");
        for (i, (st, r)) in setups.iter().zip(rewards).enumerate() {
            s += &format!("{},{},{st},{r},{},{}\n", i + 1, (i + 1) * 8, r.abs(), 0.1);
        }
        s
    }

    #[test]
    fn curriculum_stages_smoothing_and_seed_means() {
        let setups = ["6.4_2", "6.4_2", "12.8_4", "12.8_4", "18.12_6"];
        let r = parse_log(
            &p("runs/exp/D/smappo/seed0/log.csv"),
            &log(&setups, &[-10.0, -20.0, -30.0, -50.0, -70.0]),
        )
        .unwrap();
        let marks = stage_marks(&r);
        assert_eq!(
            marks,
            vec![
                (0.0, "6.4_2".to_string()),
                (16.0, "12.8_4".to_string()),
                (32.0, "18.12_6".to_string())
            ]
        );
        let sched = parse_schedule("6.4_2:16,12.8_4:16,18.12_6:8").unwrap();
        assert_eq!(sched, marks);
        assert!(parse_schedule("6.4_2").is_err());
        let st = stage_ids(&r.episodes, &marks);
        assert_eq!(st, vec![0, 0, 1, 1, 2]);
        let ys = r.values[Metric::Reward.index()].as_ref().unwrap();
        assert_eq!(
            smooth_within_stages(ys, &st, 3),
            vec![-10.0, -15.0, -30.0, -40.0, -70.0]
        );
        let c = aggregate_curves(&[
            (vec![8.0, 16.0], vec![1.0, 2.0]),
            (vec![8.0, 16.0, 24.0], vec![3.0, 6.0, 5.0]),
        ]);
        assert_eq!(
            c,
            vec![(8.0, 2.0, 1.0, 2), (16.0, 4.0, 2.0, 2), (24.0, 5.0, 0.0, 1)]
        );
        assert_eq!(fmt_tick(0.2, 0.2), "0.2");
        assert_eq!(fmt_tick(1500.0, 500.0), "1500");
        assert_eq!(ticks(0.0, 1.0, 0.25).len(), 5);
        assert_eq!(nice_range(0.0, 0.93, 5), (0.0, 1.0, 0.2));
    }

    fn is_png(path: &Path) -> bool {
        let b = std::fs::read(path).unwrap_or_default();
        b.len() > 1000 && &b[1..4] == b"PNG"
    }

    #[test]
    fn plot_files_are_written() {
        let dir = std::env::temp_dir().join(format!("tending-plot-{}", std::process::id()));
        let sub = |s: &str| {
            let d = dir.join(s);
            std::fs::create_dir_all(&d).unwrap();
            d
        };
        let e0 = sub("smappo/seed0").join("results.csv");
        let e1 = sub("smappo/seed1").join("results.csv");
        let eg = sub("greedy").join("results.csv");
        std::fs::write(&e0, EVAL_S0).unwrap();
        std::fs::write(&e1, EVAL_S1).unwrap();
        std::fs::write(&eg, EVAL_GREEDY).unwrap();
        let paper = dir.join("paper.csv");
        std::fs::write(&paper, "experiment,setup,model,mu\nX,12.8_4,smappo,0.6\n").unwrap();
        run_bars(&BarsArgs {
            files: vec![e0, e1, eg],
            out: dir.join("out/X"),
            title: "X: test".into(),
            paper: Some(paper),
            experiment: Some("X".into()),
        })
        .unwrap();
        for s in ["parts", "collisions", "mu"] {
            assert!(is_png(&dir.join(format!("out/X_{s}.png"))), "{s}");
        }
        let setups = ["6.4_2", "6.4_2", "12.8_4", "12.8_4", "18.12_6"];
        let mut logs = vec![];
        for (m, seed, k) in [("smappo", 0, 1.0), ("smappo", 1, 1.5), ("mappo", 0, 0.5)] {
            let l = sub(&format!("{m}/seed{seed}")).join("log.csv");
            let rw: Vec<f64> = (0..5).map(|i| -50.0 + k * i as f64 * 5.0).collect();
            std::fs::write(&l, log(&setups, &rw)).unwrap();
            logs.push(l);
        }
        let out = dir.join("out/X_curves.png");
        run_curves(&CurvesArgs {
            files: logs,
            out: out.clone(),
            title: "X: curves".into(),
            schedule: None,
            metrics: "reward,parts,mu".into(),
            smooth: 0,
        })
        .unwrap();
        assert!(is_png(&out));
        // Experiment A's layout: a column of panels per setup directory.
        let mut logs = vec![];
        for s in ["6.4_2", "8.6_2", "10.6_4", "12.8_4"] {
            let l = sub(&format!("A/{s}/smappo/seed0")).join("log.csv");
            std::fs::write(&l, "episodes,team_reward,mu\n8,-5,0.1\n16,-3,0.2\n").unwrap();
            logs.push(l);
        }
        let out = dir.join("out/A_curves.png");
        run_curves(&CurvesArgs {
            files: logs,
            out: out.clone(),
            title: "A".into(),
            schedule: None,
            metrics: "reward,mu".into(),
            smooth: 1,
        })
        .unwrap();
        assert!(is_png(&out));
        std::fs::remove_dir_all(&dir).ok();
    }
}
