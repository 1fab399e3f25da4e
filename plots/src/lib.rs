//! tending's pictures, drawn with plotters (the library behind `tending plot`, and the
//! curve.png and episode renders of `tending train`, `tending sim` and `tending bag render`):
//!
//! * [`chart`]: the house style every figure shares (font, sizes, palette, mesh, legend).
//! * [`training`]: a training run's curve.png; [`episode`]: an episode as GIF, SVG or PNG
//!   frames.
//! * `tending plot` ([`run`]): PNG figures of the paper's experiments (section V) from the
//!   files `tending eval` and `tending train` write ([`records`]), and `pareto` and
//!   `limits` (their modules say what they draw):
//!   * `bars`: evaluation `results.csv` files, one per trained model (a scripted baseline
//!     has one file and no training seeds). Per file, rows of the same setup (evaluation
//!     seeds) are averaged; then, per setup and model, mean and population std over files,
//!     i.e. over training seeds, the paper's "average and std as error bars" (Fig. 4, 6, 8,
//!     9). Writes one chart each for parts delivered, collisions and MU, setups on the x
//!     axis by robot count, and marks the paper's MU (`--paper`) on the MU chart.
//!   * `curves`: training `log.csv` files; per model, mean over seeds of each logged metric
//!     vs episodes with a std band (Fig. 5 and 7), and dashed lines where the curriculum
//!     stage changes (from log.csv's `setup` column, or `--schedule`).
//!
//! The model of a file is the first word of its `policy` column (eval) or the path
//! component naming a model (smappo, mappo, greedy, random); runs under a directory named
//! like a setup (experiment A's `runs/exp/A/<setup>/<model>/seed*`) get a column of panels
//! per setup.

use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, Subcommand};
use plotters::prelude::*;
use records::stats::mean_std;
use records::{finite, EvalResultRecord, PaperMuRecord, TrainLogRecord};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

mod bars;
pub mod chart;
mod curves;
mod draw;
pub mod episode;
mod limits;
mod pareto;
pub mod training;
use bars::*;
use curves::*;
use draw::{draw_bars, draw_curves};

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
    Pareto(pareto::ParetoArgs),
    /// Parts as a multiple of the best script's per setup, with the target and the ceiling
    /// the parts bound puts on any controller (issue 10).
    Limits(limits::LimitsArgs),
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
    /// Fractions (e.g. 0.5,0.7) of the first model's final value (mean of its last 100
    /// episodes) to draw as dashed levels, each marked where its curve first reaches it:
    /// the paper's Fig. 5.
    #[arg(long)]
    pub levels: Option<String>,
}

pub fn run(a: PlotArgs) -> Result<()> {
    match a.kind {
        PlotKind::Bars(b) => run_bars(&b),
        PlotKind::Curves(c) => run_curves(&c),
        PlotKind::Pareto(p) => pareto::run(&p),
        PlotKind::Limits(l) => limits::run(&l),
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

/// The legend text of a model: scripted, or how many training seeds it averages.
fn model_label(m: &str, n: usize) -> String {
    if is_scripted(m) {
        format!("{m} (scripted)")
    } else if n == 1 {
        format!("{m} (1 seed)")
    } else {
        format!("{m} ({n} seeds)")
    }
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
        const HEAD: &str = "policy,setup,seed,episodes,parts_delivered,collisions,mu,team_reward\n";
        let e = parse_eval(&f, HEAD).unwrap_err();
        assert!(e.to_string().contains("no data rows"), "{e}");
        let e = parse_eval(&f, "policy,setup,parts_delivered,collisions\ng,6.4_2,1,2\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("runs/x/eval/results.csv") && e.contains("`seed`"),
            "{e}"
        );
        let e = parse_eval(
            &f,
            &format!("{HEAD}g,6.4_2,0,1,1,2,0.1,0\ng,6.4_2,1,1,x,2,0.1,0\n"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("results.csv:3") && e.contains("parts_delivered"),
            "{e}"
        );
        let e = parse_eval(&f, &format!("{HEAD}g,6.4_2,0,1,1,2,NaN,0\n"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("results.csv:2") && e.contains("`mu` is NaN"),
            "{e}"
        );
        let e = parse_eval(&f, &format!("{HEAD}g,6.4_2,0,1,1,2,0.1\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("results.csv:2") && e.contains("7 fields"), "{e}");
        let e = parse_log(
            &p("r/log.csv"),
            &log(&["6.4_2", "6.4_2"], &[1.0, 2.0]).replace("\n2,16,", "\n2,8,"),
        )
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

    /// A log.csv of 8 episodes per update, as `tending train` writes it.
    fn log(setups: &[&str], rewards: &[f64]) -> String {
        let rows: Vec<TrainLogRecord> = setups
            .iter()
            .zip(rewards)
            .enumerate()
            .map(|(i, (st, r))| TrainLogRecord {
                update: i as u64 + 1,
                episodes: (i as u64 + 1) * 8,
                setup: st.to_string(),
                team_reward: *r,
                parts_delivered: r.abs(),
                mu: 0.1,
                ..Default::default()
            })
            .collect();
        records::to_text(&rows).unwrap()
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
        let ys = &r.values[Metric::Reward.index()];
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
        assert_eq!(draw::nice_range(0.0, 0.93, 5), (0.0, 1.0, 0.2));
    }

    #[test]
    fn levels_are_fractions_of_the_final_mean_reached_on_the_drawn_curve() {
        // raw seed-mean: 0, 100, 200 ... at 8, 16, 24 ... episodes; final = mean of the
        // points after (last - 100) episodes
        let raw: Curve = (1..=20)
            .map(|i| (i as f64 * 8.0, (i - 1) as f64 * 100.0, 0.0, 2))
            .collect();
        let fin = raw
            .iter()
            .filter(|p| p.0 > 160.0 - 100.0)
            .map(|p| p.1)
            .sum::<f64>()
            / 13.0;
        let smoothed: Curve = raw.iter().map(|p| (p.0, p.1 - 50.0, 0.0, 2)).collect();
        let ls = levels(&raw, &smoothed, &[0.5, 0.7], 100.0).unwrap();
        assert!((ls[0].value - 0.5 * fin).abs() < 1e-9, "{ls:?}");
        // first smoothed point >= 0.5 * fin
        let want = smoothed.iter().find(|p| p.1 >= 0.5 * fin).unwrap().0;
        assert_eq!(ls[0].hit, Some(want));
        assert!(ls[1].hit.unwrap() > want);
        // a level above every point is never reached; a non-positive final has no levels
        let flat: Curve = raw.iter().map(|p| (p.0, 10.0, 0.0, 1)).collect();
        assert_eq!(levels(&raw, &flat, &[1.0], 100.0).unwrap()[0].hit, None);
        let neg: Curve = raw.iter().map(|p| (p.0, -p.1, 0.0, 1)).collect();
        assert!(levels(&neg, &neg, &[0.5], 100.0).is_none());
        assert_eq!(parse_levels("0.5, 0.7").unwrap(), vec![0.5, 0.7]);
        for bad in ["0", "1.5", "x"] {
            let e = parse_levels(bad).unwrap_err().to_string();
            assert!(e.contains("--levels") && e.contains(bad), "{e}");
        }
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
            levels: None,
        })
        .unwrap();
        assert!(is_png(&out));
        // Experiment A's layout: a column of panels per setup directory.
        let mut logs = vec![];
        for s in ["6.4_2", "8.6_2", "10.6_4", "12.8_4"] {
            let l = sub(&format!("A/{s}/smappo/seed0")).join("log.csv");
            std::fs::write(&l, log(&[s, s], &[-5.0, -3.0])).unwrap();
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
            levels: Some("0.5,0.7".into()),
        })
        .unwrap();
        assert!(is_png(&out));
        std::fs::remove_dir_all(&dir).ok();
    }
}
