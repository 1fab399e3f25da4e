//! `tending bag ...` and `tending record`: rosbag2 MCAP bags of a fleet (see the `bag` crate
//! and docs/adr/0002-rosbag-mcap.md).
//!
//! * `bag info`: topics, types, QoS, counts, duration.
//! * `bag metrics`: parts delivered, collisions, MU and robots over time, from
//!   `/tending/metrics` when recorded and independently from `has_part` transitions
//!   (true -> false = a delivery, false -> true = a pick) and pose topics.
//! * `bag recover`: rewrite a bag cut by SIGKILL into a complete one.
//! * `bag render`: GIF/SVG/PNG frames of the poses and part_ready flags.
//! * `bag play`: republish every message with its topic's original QoS and timing.
//! * `record`: subscribe to every contract topic found by discovery and write a bag until
//!   Ctrl-C / SIGTERM (the bag is finalized on both) or `--duration`.
//!
//! One file per verb in `bag_cmd/`; the bag format and the metrics are the `bag` crate's.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Result};
use bag::{BagReader, BagWriter};
use clap::{Args, Subcommand};
use msgs::topics::{self, Entity, Leaf};
use msgs::{
    schema, Bool, Clock, DiagnosticArray, MarkerArray, MsgDef, PoseStamped, Profile, RosMessage,
    StdString, Time, Twist,
};
use ros2_client::dds::{Node, Publisher, Subscription};
use ros2_client::qos::{Durability, History, Reliability};
use ros2_client::QosProfile;

#[derive(Args)]
pub struct BagArgs {
    #[command(subcommand)]
    cmd: BagCmd,
}

#[derive(Subcommand)]
enum BagCmd {
    /// Topics, types, QoS, message counts, duration and completeness of a bag.
    Info { bag: PathBuf },
    /// Parts delivered, collisions, MU and robots over time, recomputed from the bag alone.
    Metrics {
        bag: PathBuf,
        /// Table row period, seconds of bag time.
        #[arg(long, default_value_t = 1.0)]
        period: f64,
    },
    /// Rewrite a bag cut by SIGKILL (no summary/footer) into a complete bag directory.
    Recover { input: PathBuf, output: PathBuf },
    /// Draw robots, machines and storages from the poses: .gif, .svg (last frame) or a
    /// directory of PNG frames.
    Render {
        bag: PathBuf,
        out: PathBuf,
        /// Bag time between frames, seconds.
        #[arg(long, default_value_t = 0.1)]
        frame_period: f64,
    },
    /// Republish every message on its topic with its original QoS and timing.
    Play {
        bag: PathBuf,
        #[arg(long, default_value_t = 1.0)]
        rate: f64,
        /// ROS domain (default: ROS_DOMAIN_ID or 0).
        #[arg(long)]
        domain_id: Option<u16>,
        /// Seconds to wait for subscribers to match before the first message.
        #[arg(long, default_value_t = 1.0)]
        wait: f64,
        /// DDS Security enclave, used when ROS_SECURITY_ENABLE=true (with
        /// ROS_SECURITY_KEYSTORE; see `tending security`).
        #[arg(long, default_value = keystore::PLAYER_ENCLAVE)]
        enclave: String,
    },
    /// Test helper: write a synthetic fleet episode (contract topics) as a bag; with
    /// --realtime it paces itself like a recorder and finalizes on SIGINT/SIGTERM.
    #[command(hide = true)]
    Synth {
        dir: PathBuf,
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        #[arg(long, default_value_t = 2)]
        robots: usize,
        #[arg(long)]
        realtime: bool,
    },
}

#[derive(Args)]
pub struct RecordArgs {
    /// The bag directory to create.
    dir: PathBuf,
    /// Stop after this many seconds (default: until Ctrl-C / SIGTERM).
    #[arg(long)]
    duration: Option<f64>,
    /// ROS domain (default: ROS_DOMAIN_ID or 0).
    #[arg(long)]
    domain_id: Option<u16>,
    /// Seconds between topic discovery scans.
    #[arg(long, default_value_t = 0.5)]
    discovery_period: f64,
    /// DDS Security enclave, used when ROS_SECURITY_ENABLE=true (with
    /// ROS_SECURITY_KEYSTORE; see `tending security`).
    #[arg(long, default_value = keystore::RECORDER_ENCLAVE)]
    enclave: String,
}

pub fn run(a: BagArgs) -> Result<()> {
    match a.cmd {
        BagCmd::Info { bag } => info(&bag),
        BagCmd::Metrics { bag, period } => metrics(&bag, period),
        BagCmd::Recover { input, output } => {
            let r = bag::recover(&input, &output)?;
            println!(
                "recovered {} messages on {} topics from {} ({}) into {}",
                r.messages,
                r.topics,
                r.input.display(),
                if r.input_was_complete {
                    "complete file".to_string()
                } else {
                    format!(
                        "cut file: {}",
                        r.stopped_early.as_deref().unwrap_or("no footer")
                    )
                },
                output.display()
            );
            Ok(())
        }
        BagCmd::Render {
            bag,
            out,
            frame_period,
        } => render(&bag, &out, frame_period),
        BagCmd::Play {
            bag,
            rate,
            domain_id,
            wait,
            enclave,
        } => play(&bag, rate, domain_id, wait, &enclave),
        BagCmd::Synth {
            dir,
            duration,
            robots,
            realtime,
        } => synth(&dir, duration, robots, realtime),
    }
}

mod info;
mod metrics;
mod play;
mod record;
mod render;
mod synth;

use info::{info, qos_from_yaml};
use metrics::metrics;
use play::play;
pub use record::record;
use record::{domain, ros_node, wall_ns};
use render::render;
use synth::synth;

fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}
