//! Process set-up every node binary repeats: the stop flag set by signals, and tracing.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{Context as _, Result};

/// A flag set by SIGINT or SIGTERM (and SIGHUP: ctrlc's `termination` feature); the
/// loops poll it and shut down cleanly (zero commands, finished bags).
pub fn stop_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    ctrlc::set_handler(move || s.store(true, Ordering::SeqCst))
        .context("cannot install the SIGINT/SIGTERM handler")?;
    Ok(stop)
}

/// Log to stderr through tracing: `RUST_LOG` if set, else `level` (`--log-level`,
/// default info) with RustDDS and ros2-client at warn (they are chatty at info) except
/// ros2-client's rosout lines, which are the node's own log.
pub fn init_tracing(level: Option<&str>) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        let lvl = level.unwrap_or("info");
        tracing_subscriber::EnvFilter::new(format!(
            "{lvl},rustdds=warn,ros2_client=warn,ros2_client::rosout={lvl}"
        ))
    });
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
}

/// A warning from the runtime: through tracing when the process set it up (the nodes),
/// else on stderr (the `tending` CLI has no subscriber).
pub(crate) fn report(msg: &str) {
    if tracing::dispatcher::has_been_set() {
        tracing::warn!("{msg}");
    } else {
        eprintln!("{msg}");
    }
}
