//! `sim_bridge` binary: parse ROS 2 arguments, run the bridge until Ctrl-C / SIGTERM or
//! `max_steps`.

use ros::args::ArgError;
use sim_bridge::params;
use sim_bridge::watchdog::{Limits, Watchdog, EXIT_WATCHDOG};

fn main() {
    let env_domain = std::env::var("ROS_DOMAIN_ID").ok();
    let (p, warnings) = match params::parse(std::env::args().skip(1), env_domain.as_deref()) {
        Ok(x) => x,
        Err(ArgError::Help) => {
            println!("{}", params::USAGE);
            std::process::exit(0);
        }
        Err(e) => {
            eprintln!("sim_bridge: error: {e}\n{}", params::USAGE);
            std::process::exit(2);
        }
    };
    ros::init_tracing(p.node.log_level.as_deref());
    for w in &warnings {
        tracing::warn!("{w}");
    }
    let stop = match ros::stop_flag() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("sim_bridge: error: {e:#}");
            std::process::exit(1);
        }
    };
    // Exit with code 75 (EX_TEMPFAIL) when start-up or the step loop hangs, so that
    // `tending fleet` restarts the bridge instead of running a dead fleet.
    let wd = Watchdog::new(Limits::from_secs(p.startup_timeout_s, p.stall_timeout_s));
    let watching = wd.spawn(|stuck| {
        eprintln!("sim_bridge: watchdog: {stuck}");
        std::process::exit(EXIT_WATCHDOG);
    });
    if let Err(e) = watching {
        eprintln!("sim_bridge: error: cannot start the watchdog thread: {e}");
        std::process::exit(1);
    }
    if let Err(e) = sim_bridge::node::run_watched(p, &stop, &wd) {
        tracing::error!("{e:#}");
        std::process::exit(1);
    }
}
