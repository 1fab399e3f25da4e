//! `robot_node` binary: parse ROS 2 arguments, run the node until Ctrl-C / SIGTERM.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use robot_node::args::{self, ArgError};

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

    match robot_node::node::run(&params, &stop) {
        Ok(_) => {}
        Err(e) => {
            tracing::error!("{e:#}");
            std::process::exit(1);
        }
    }
}
