//! `tending plot curves`: training log.csv files, per model the mean and std over seeds of
//! each metric against episodes, smoothed within curriculum stages.

use super::*;

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Metric {
    Reward,
    Parts,
    Collisions,
    Mu,
}

impl Metric {
    pub(super) fn parse(s: &str) -> Result<Metric> {
        Ok(match s.trim() {
            "reward" | "team_reward" => Metric::Reward,
            "parts" | "parts_delivered" => Metric::Parts,
            "collisions" => Metric::Collisions,
            "mu" | "MU" => Metric::Mu,
            o => bail!("unknown metric `{o}`: expected reward, parts, collisions or mu"),
        })
    }
    const ALL: [Metric; 4] = [
        Metric::Reward,
        Metric::Parts,
        Metric::Collisions,
        Metric::Mu,
    ];
    /// This metric's column of a log row.
    fn of(self, r: &TrainLogRecord) -> (&'static str, f64) {
        match self {
            Metric::Reward => ("team_reward", r.team_reward),
            Metric::Parts => ("parts_delivered", r.parts_delivered),
            Metric::Collisions => ("collisions", r.collisions),
            Metric::Mu => ("mu", r.mu),
        }
    }
    pub(super) fn title(self) -> &'static str {
        match self {
            Metric::Reward => "team reward",
            Metric::Parts => "parts delivered",
            Metric::Collisions => "collisions",
            Metric::Mu => "MU",
        }
    }
    pub(super) fn index(self) -> usize {
        self as usize
    }
}

/// The final value `--levels` takes fractions of: the mean of the last this many episodes
/// (the window of the paper's Table I protocol).
pub(super) const FINAL_WINDOW: f64 = 100.0;

/// One training run's log.
#[derive(Debug, Clone)]
pub(super) struct LogRun {
    pub(super) model: String,
    pub(super) group: Option<String>,
    pub(super) episodes: Vec<f64>,
    pub(super) setups: Vec<String>,
    /// Per metric (Metric::index), its column.
    pub(super) values: [Vec<f64>; 4],
}

pub(super) fn parse_log(path: &Path, text: &str) -> Result<LogRun> {
    let rows = records::parse::<TrainLogRecord>(path, text)?;
    if let Some(w) = rows
        .windows(2)
        .find(|w| w[1].record.episodes <= w[0].record.episodes)
    {
        bail!(
            "{}:{}: episodes {} do not increase (previous row {})",
            path.display(),
            w[1].line,
            w[1].record.episodes,
            w[0].record.episodes
        );
    }
    let mut values: [Vec<f64>; 4] = Default::default();
    for m in Metric::ALL {
        values[m.index()] = rows
            .iter()
            .map(|l| {
                let (column, v) = m.of(&l.record);
                finite(path, l.line, column, v)
            })
            .collect::<Result<_>>()?;
    }
    let model = model_from_path(path).unwrap_or_else(|| {
        path.parent()
            .and_then(|p| p.file_name())
            .and_then(|f| f.to_str())
            .unwrap_or("run")
            .to_string()
    });
    Ok(LogRun {
        model,
        group: group_from_path(path),
        episodes: rows.iter().map(|l| l.record.episodes as f64).collect(),
        setups: rows.iter().map(|l| l.record.setup.clone()).collect(),
        values,
    })
}

/// Stage starts (episodes, setup) of a schedule `SETUP:EPISODES,...`.
pub(super) fn parse_schedule(s: &str) -> Result<Vec<(f64, String)>> {
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
pub(super) fn stage_marks(run: &LogRun) -> Vec<(f64, String)> {
    let setups = &run.setups;
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
pub(super) fn stage_ids(episodes: &[f64], marks: &[(f64, String)]) -> Vec<usize> {
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
pub(super) fn smooth_within_stages(xs: &[f64], stage: &[usize], w: usize) -> Vec<f64> {
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
pub(super) type Curve = Vec<(f64, f64, f64, usize)>;

pub(super) fn aggregate_curves(series: &[(Vec<f64>, Vec<f64>)]) -> Curve {
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

pub(super) struct CurveGroup {
    pub(super) name: Option<String>,
    pub(super) marks: Vec<(f64, String)>,
    /// model -> (runs, per metric curve)
    pub(super) models: Vec<(String, usize, Vec<Curve>)>,
    pub(super) x_max: f64,
    /// Per metric, the `--levels` marks of the group's first model (empty without them).
    pub(super) levels: Vec<Vec<Level>>,
}

/// A fraction of a model's final value and where its curve first reaches it: the paper's
/// Fig. 5 draws 50 % and 70 % of SMAPPO's "final convergence value" this way.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Level {
    pub(super) frac: f64,
    /// frac x the final value.
    pub(super) value: f64,
    /// The first episode count at which the drawn (smoothed) mean reaches `value`.
    pub(super) hit: Option<f64>,
}

/// `--levels` of one model's metric: the final value is the mean of the unsmoothed
/// seed-mean over the last `window` episodes (as bench/experiments/verdict.py judges Fig. 5),
/// the hit is read on the smoothed curve that is drawn. None when the final value is not
/// positive: a fraction of it says nothing about progress.
pub(super) fn levels(
    raw: &Curve,
    smoothed: &Curve,
    fracs: &[f64],
    window: f64,
) -> Option<Vec<Level>> {
    let last = raw.last()?.0;
    let tail: Vec<f64> = raw
        .iter()
        .filter(|p| p.0 > last - window)
        .map(|p| p.1)
        .collect();
    let fin = tail.iter().sum::<f64>() / tail.len() as f64;
    if fin <= 0.0 {
        return None;
    }
    Some(
        fracs
            .iter()
            .map(|&frac| {
                let value = frac * fin;
                let hit = smoothed.iter().find(|p| p.1 >= value).map(|p| p.0);
                Level { frac, value, hit }
            })
            .collect(),
    )
}

/// `--levels`: fractions in (0, 1], comma-separated.
pub(super) fn parse_levels(s: &str) -> Result<Vec<f64>> {
    s.split(',')
        .filter(|p| !p.trim().is_empty())
        .map(|p| match p.trim().parse::<f64>() {
            Ok(f) if f > 0.0 && f <= 1.0 => Ok(f),
            _ => bail!("--levels: `{p}` is not a fraction in (0, 1]"),
        })
        .collect()
}

pub(super) fn build_groups(
    runs: &[LogRun],
    metrics: &[Metric],
    schedule: &Option<Vec<(f64, String)>>,
    smooth: usize,
    fracs: &[f64],
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
            // --levels: of the first model (SMAPPO when it is there), unsmoothed for its
            // final value
            let levels = match (models.first(), fracs.is_empty()) {
                (Some(lead), false) => {
                    let mine: Vec<&&LogRun> = rs.iter().filter(|r| &r.model == lead).collect();
                    metrics
                        .iter()
                        .map(|metric| {
                            let series = |w: usize| -> Curve {
                                let s: Vec<(Vec<f64>, Vec<f64>)> = mine
                                    .iter()
                                    .map(|r| {
                                        let st = stage_ids(&r.episodes, &stage_marks(r));
                                        let ys = &r.values[metric.index()];
                                        (r.episodes.clone(), smooth_within_stages(ys, &st, w))
                                    })
                                    .collect();
                                aggregate_curves(&s)
                            };
                            levels(&series(1), &series(smooth), fracs, FINAL_WINDOW)
                                .unwrap_or_default()
                        })
                        .collect()
                }
                _ => vec![],
            };
            let models = models
                .into_iter()
                .map(|m| {
                    let mine: Vec<&&LogRun> = rs.iter().filter(|r| r.model == m).collect();
                    let curves = metrics
                        .iter()
                        .map(|metric| {
                            let series: Vec<(Vec<f64>, Vec<f64>)> = mine
                                .iter()
                                .map(|r| {
                                    let ys = &r.values[metric.index()];
                                    // a log's own stages (its setup column) smooth it
                                    let st = stage_ids(&r.episodes, &stage_marks(r));
                                    (r.episodes.clone(), smooth_within_stages(ys, &st, smooth))
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
                levels,
            }
        })
        .collect()
}

pub(super) fn run_curves(a: &CurvesArgs) -> Result<()> {
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
    let longest = runs.iter().map(|r| r.episodes.len()).max().unwrap_or(1);
    let smooth = if a.smooth > 0 {
        a.smooth
    } else {
        (longest / 20).max(1)
    };
    let fracs = a
        .levels
        .as_deref()
        .map(parse_levels)
        .transpose()?
        .unwrap_or_default();
    let groups = build_groups(&runs, &metrics, &schedule, smooth, &fracs);
    for g in &groups {
        for (metric, ls) in metrics.iter().zip(&g.levels) {
            for l in ls {
                let at = l.hit.map_or("never".into(), |x| format!("at {x} episodes"));
                eprintln!(
                    "{}{}: {:.0} % of the final {} ({:.3}) reached {at}",
                    g.name.as_deref().map_or(String::new(), |n| format!("{n} ")),
                    g.models[0].0,
                    l.frac * 100.0,
                    metric.title(),
                    l.value / l.frac,
                );
            }
        }
    }
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
