//! `robot_node` binary: parse ROS 2 arguments, run the node until Ctrl-C / SIGTERM.
//!
//! Exit codes: 0 stopped, 1 error, 2 bad arguments, 75 (`EX_TEMPFAIL`) the watchdog ended a
//! hung start-up or control loop ([`robot_node::watchdog`]; a restart usually succeeds).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

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

    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        let lvl = params.log_level.as_deref().unwrap_or("info");
        // RustDDS and ros2-client are chatty at info
        tracing_subscriber::EnvFilter::new(format!(
            "{lvl},rustdds=warn,ros2_client=warn,ros2_client::rosout={lvl}"
        ))
    });
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    for w in &warnings {
        tracing::warn!("{w}");
    }

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        if let Err(e) = ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)) {
            eprintln!("robot_node: error: cannot install the signal handler: {e}");
            std::process::exit(1);
        }
    }

    // Exit with code 75 (EX_TEMPFAIL) when start-up or the control loop hangs, so that the
    // launcher restarts the node (the safety net under the fixed RustDDS deadlock, ADR 0005)
    let wd = Watchdog::new(Limits::from_secs(
        params.startup_timeout_s,
        params.stall_timeout_s,
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
