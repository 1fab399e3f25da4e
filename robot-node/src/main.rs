//! `robot_node` binary: parse ROS 2 arguments, run the node until Ctrl-C / SIGTERM.
//!
//! Exit codes: 0 stopped, 1 error, 2 bad arguments, 75 (`EX_TEMPFAIL`) the watchdog ended a
//! hung start-up or control loop ([`robot_node::watchdog`]; a restart usually succeeds).

use robot_node::args::{self, ArgError};
use robot_node::watchdog::{Limits, Watchdog, EXIT_WATCHDOG};

fn main() {
    let env_domain = std::env::var("ROS_DOMAIN_ID").ok();
    let (params, warnings) = match args::parse(std::env::args().skip(1), env_domain.as_deref()) {
        Ok(x) => x,
        Err(ArgError::Help) => {
            println!("{}", args::USAGE);
            std::process::exit(0);
        }
        Err(e) => {
            eprintln!("robot_node: error: {e}\n{}", args::USAGE);
            std::process::exit(2);
        }
    };

    ros::init_tracing(params.node.log_level.as_deref());
    for w in &warnings {
        tracing::warn!("{w}");
    }

    let stop = match ros::stop_flag() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("robot_node: error: {e:#}");
            std::process::exit(1);
        }
    };

    // Exit with code 75 (EX_TEMPFAIL) when start-up or the control loop hangs, so that the
    // launcher restarts the node (the safety net under the fixed RustDDS deadlock, ADR 0005)
    let wd = Watchdog::new(Limits::from_secs(
        params.watchdog.startup_timeout_s,
        params.watchdog.stall_timeout_s,
    ));
    let watching = wd.spawn(|stuck| {
        eprintln!("robot_node: watchdog: {stuck}");
        std::process::exit(EXIT_WATCHDOG);
    });
    if let Err(e) = watching {
        eprintln!("robot_node: error: cannot start the watchdog thread: {e}");
        std::process::exit(1);
    }

    match robot_node::node::run_watched(&params, &stop, &wd) {
        Ok(_) => {}
        Err(e) => {
            tracing::error!("{e:#}");
            std::process::exit(1);
        }
    }
}
