//! DDS context and ROS 2 node lifecycle.
//!
//! ros2-client's `Context::new()` ignores `ROS_DOMAIN_ID`, and a node's graph events
//! (discovery, parameters, rosout) only arrive while its spinner runs: [`context`] takes
//! the domain explicitly, [`RosNode`] owns a node and the thread spinning it.

use std::fmt::Debug;
use std::thread::JoinHandle;

use anyhow::Result;
use ros2_client::dds::{Context, ContextOptions, Node};
use ros2_client::{NodeName, NodeOptions};

use crate::security::{self, Security, SecurityEnv};

/// Map a ros2-client or RustDDS error (they implement `Debug` only) to an error naming
/// what failed.
pub fn dds_err<E: Debug>(what: &str) -> impl FnOnce(E) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("{what}: {e:?}")
}

/// A DDS context (participant) on ROS domain `domain_id`, secured as the ROS security
/// environment says (`ROS_SECURITY_*`, with `enclave` from `--enclave`; see
/// [`crate::security`]). With Enforce and no valid enclave this is the error that stops
/// the process.
pub fn context(domain_id: u16, enclave: Option<&str>) -> Result<Context> {
    let sec = security::resolve(&SecurityEnv::from_env(), enclave, crate::process::report)?;
    context_with(domain_id, &sec)
}

/// A DDS context on `domain_id` with `security` decided by the caller.
pub fn context_with(domain_id: u16, security: &Security) -> Result<Context> {
    let opts = ContextOptions::new().domain_id(domain_id);
    match security {
        Security::Off => Context::with_options(opts).map_err(dds_err("DDS context")),
        Security::Enclave { enclave, dir } => {
            if domain_id > msgs::enclave::MAX_SECURE_DOMAIN {
                anyhow::bail!(
                    "DDS Security: domain {domain_id} is above {max}, the last domain a \
                     keystore's governance and permissions cover (Cyclone DDS reads no \
                     document naming a domain above 230); use ROS_DOMAIN_ID 0..={max}; \
                     refusing to start",
                    max = msgs::enclave::MAX_SECURE_DOMAIN
                );
            }
            // Our keys are not password-protected (as SROS2's); the files are the
            // rmw_dds_common names, which ros2-client's security option reads.
            let opts = opts.enable_security(dir, String::new());
            Context::with_options(opts).map_err(|e| {
                anyhow::anyhow!(
                    "DDS Security refused enclave `{enclave}` ({}): {e:?}; refusing to start",
                    dir.display()
                )
            })
        }
    }
}

/// The identity of a node: namespace (`/` or `/robot_3`), name, and whether it logs to
/// `/rosout`.
#[derive(Debug, Clone)]
pub struct NodeSpec<'a> {
    pub namespace: &'a str,
    pub name: &'a str,
    pub enable_rosout: bool,
}

/// A node on `ctx` that nobody spins (enough for plain publish/subscribe; no graph events).
pub fn node(ctx: &Context, spec: &NodeSpec) -> Result<Node> {
    ctx.new_node(
        NodeName::new(spec.namespace, spec.name).map_err(dds_err("node name"))?,
        NodeOptions::new().enable_rosout(spec.enable_rosout),
    )
    .map_err(dds_err("create node"))
}

/// A node and the thread spinning it (a smol executor); dropping it stops the spinner.
pub struct RosNode {
    ctx: Context,
    node: Option<Node>,
    spin: Option<JoinHandle<()>>,
}

impl RosNode {
    /// Create the node on `ctx` and start its spinner on a thread named `thread`.
    pub fn start(ctx: &Context, spec: &NodeSpec, thread: &str) -> Result<Self> {
        let mut node = node(ctx, spec)?;
        let spinner = node.spinner().map_err(dds_err("spinner"))?;
        let spin = std::thread::Builder::new()
            .name(thread.into())
            .spawn(move || {
                if let Err(e) = smol::block_on(spinner.spin()) {
                    crate::process::report(&format!("spinner stopped with error: {e:?}"));
                }
            })?;
        Ok(Self {
            ctx: ctx.clone(),
            node: Some(node),
            spin: Some(spin),
        })
    }

    pub fn context(&self) -> &Context {
        &self.ctx
    }

    pub fn node(&mut self) -> &mut Node {
        self.node.as_mut().expect("the node lives until drop")
    }

    /// The context and the node at once (creating writers needs both).
    pub fn parts(&mut self) -> (&Context, &mut Node) {
        (
            &self.ctx,
            self.node.as_mut().expect("the node lives until drop"),
        )
    }
}

impl Drop for RosNode {
    fn drop(&mut self) {
        drop(self.node.take()); // signals the spinner to stop
        if let Some(h) = self.spin.take() {
            if h.join().is_err() {
                crate::process::report("spinner thread panicked");
            }
        }
    }
}
