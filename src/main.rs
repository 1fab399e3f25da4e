//! `tending`: the command line of the project: simulate, evaluate, train, run a ROS 2 fleet,
//! record and read bags, plot, benchmark. Thin commands: the logic is in the crates below.

mod bag_cmd;
mod bench_sim;
mod bound_cmd;
mod eval_cmd;
mod method;
mod security_cmd;
mod sim_cmd;
mod train_cmd;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "tending",
    version,
    about = "Decentralized multi-robot machine tending (SMAPPO)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run episodes of a setup with a scripted policy and print the paper's metrics.
    Sim(sim_cmd::SimArgs),
    /// Run a fleet: one sim_bridge and one robot_node process per robot, live metrics.
    Fleet(fleet::FleetArgs),
    /// Measure simulator throughput (agent-steps/s) and write a Markdown report.
    BenchSim(bench_sim::BenchArgs),
    /// Train SMAPPO or MAPPO with PPO (progress, log.csv, curve.png, checkpoints, resume).
    Train(train_cmd::TrainArgs),
    /// Evaluate a checkpoint or a scripted baseline over setups and seeds (paper tables).
    Eval(eval_cmd::EvalArgs),
    /// The most parts any controller could deliver on eval's layouts (sim::parts_bound).
    Bound(bound_cmd::BoundArgs),
    /// rosbag2 MCAP bags: info, metrics, recover, render, play.
    Bag(bag_cmd::BagArgs),
    /// Record every contract topic of a running fleet into a bag until Ctrl-C / SIGTERM.
    Record(bag_cmd::RecordArgs),
    /// PNG figures of the experiments: eval bar charts, training curves (docs/experiments).
    Plot(plots::PlotArgs),
    /// DDS Security keystores (SROS2 layout): create, add an enclave, revoke, list.
    Security(security_cmd::SecurityArgs),
    /// Print the default scenario config (TOML) to start a custom one from.
    Config,
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Sim(a) => sim_cmd::run(a),
        Cmd::Fleet(a) => fleet::run(a),
        Cmd::BenchSim(a) => bench_sim::run(a),
        Cmd::Train(a) => train_cmd::run(a),
        Cmd::Eval(a) => eval_cmd::run(a),
        Cmd::Bound(a) => bound_cmd::run(a),
        Cmd::Bag(a) => bag_cmd::run(a),
        Cmd::Record(a) => bag_cmd::record(a),
        Cmd::Plot(a) => plots::run(a),
        Cmd::Security(a) => security_cmd::run(a),
        Cmd::Config => {
            print!("{}", sim::ScenarioConfig::default().to_toml());
            Ok(())
        }
    };
    // An expected failure is one line naming its cause (with its context chain), never a
    // Rust backtrace: those stay in the children's logs.
    match r {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("tending: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
