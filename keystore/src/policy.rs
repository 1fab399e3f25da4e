//! Who may publish and subscribe what: the permissions of each kind of enclave, as DDS
//! topic names (`rt/` + the ROS name; DDS Security matches them as globs, `*` also
//! across `/`).
//!
//! Every node of ros2-client publishes `ros_discovery_info`, `rt/rosout` and
//! `rt/parameter_events`, reads `ros_discovery_info`, `rt/parameter_events` and `rt/clock`
//! (its spinner's sim time), and serves its parameters (`rq/<node>/...Request` in,
//! `rr/<node>/...Reply` out). Beyond that:
//!
//! | enclave | publishes | subscribes |
//! |---|---|---|
//! | robot (one per robot, or per process hosting several) | `rt/<robot>/cmd_vel` of its own robots only | poses, has_part, part_ready, clock |
//! | bridge | poses, has_part, part_ready, clock, markers, metrics | every `cmd_vel`, `rt/tending/command` |
//! | recorder | nothing of the contract | every topic |

use msgs::topics;

/// One enclave's grant: DDS topic name patterns it may publish and subscribe.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Grant {
    pub publish: Vec<String>,
    pub subscribe: Vec<String>,
}

/// The kinds of enclave a fleet needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Role {
    /// A `robot_node` process commanding these robots (namespaces without the leading
    /// slash, e.g. `robot_3`); it may publish only their `cmd_vel`.
    Robots(Vec<String>),
    /// `sim_bridge` (on hardware: the drivers): the world state out, commands in.
    Bridge,
    /// `tending record`: reads everything, publishes nothing of the contract.
    Recorder,
    /// `tending bag play`: publishes what a bag holds (the bridge's topics and commands).
    Player,
}

/// `rt/...` for a ROS topic name (`/robot_3/cmd_vel` -> `rt/robot_3/cmd_vel`).
pub fn dds_topic(ros_name: &str) -> String {
    format!("rt/{}", ros_name.trim_start_matches('/'))
}

/// What every ros2-client node publishes and reads (graph, logging, parameters, clock).
fn node_basics(grant: &mut Grant) {
    for t in [
        "ros_discovery_info",
        "rt/rosout",
        "rt/parameter_events",
        "rr/*",
    ] {
        grant.publish.push(t.into());
    }
    for t in ["ros_discovery_info", "rt/parameter_events", "rq/*"] {
        grant.subscribe.push(t.into());
    }
    grant.subscribe.push(dds_topic(topics::CLOCK));
}

/// The topics sim_bridge publishes (the world state).
fn world_state() -> Vec<String> {
    vec![
        "rt/*/pose".into(),
        "rt/*/has_part".into(),
        "rt/*/part_ready".into(),
        dds_topic(topics::CLOCK),
        dds_topic(topics::MARKERS),
        dds_topic(topics::METRICS),
    ]
}

impl Role {
    /// The grant of an enclave of this role.
    pub fn grant(&self) -> Grant {
        let mut g = Grant {
            publish: Vec::new(),
            subscribe: Vec::new(),
        };
        node_basics(&mut g);
        match self {
            Role::Robots(names) => {
                for n in names {
                    g.publish.push(dds_topic(&format!("/{n}/cmd_vel")));
                }
                g.subscribe.extend([
                    "rt/*/pose".into(),
                    "rt/*/has_part".into(),
                    "rt/*/part_ready".into(),
                ]);
            }
            Role::Bridge => {
                g.publish.extend(world_state());
                g.subscribe
                    .extend(["rt/*/cmd_vel".into(), dds_topic(topics::COMMAND)]);
            }
            Role::Recorder => g.subscribe.push("rt/*".into()),
            Role::Player => {
                g.publish.extend(world_state());
                g.publish.push("rt/*/cmd_vel".into());
            }
        }
        g
    }

    /// A role from its command-line form: `bridge`, `recorder`, `player` or
    /// `robots:robot_0,robot_1`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "bridge" => Ok(Role::Bridge),
            "recorder" => Ok(Role::Recorder),
            "player" => Ok(Role::Player),
            _ => {
                let Some(list) = s.strip_prefix("robots:") else {
                    return Err(format!(
                        "role `{s}`: expected bridge, recorder, player or robots:NAME[,NAME...]"
                    ));
                };
                let names: Vec<String> = list.split(',').map(|n| n.trim().to_string()).collect();
                for n in &names {
                    if n.is_empty() || !n.split('/').all(valid_segment) {
                        return Err(format!(
                            "role `{s}`: `{n}` is not a robot namespace (e.g. robot_3)"
                        ));
                    }
                }
                Ok(Role::Robots(names))
            }
        }
    }
}

/// A ROS name segment; also keeps glob characters out of a robot's own topic.
fn valid_segment(seg: &str) -> bool {
    !seg.is_empty()
        && (seg.as_bytes()[0].is_ascii_alphabetic() || seg.as_bytes()[0] == b'_')
        && seg.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_may_publish_only_its_own_cmd_vel() {
        let g = Role::Robots(vec!["robot_3".into()]).grant();
        let cmd: Vec<_> = g.publish.iter().filter(|t| t.contains("cmd_vel")).collect();
        assert_eq!(cmd, ["rt/robot_3/cmd_vel"]);
        assert!(g.subscribe.contains(&"rt/*/pose".to_string()));
        assert!(!g.subscribe.iter().any(|t| t.contains("cmd_vel")));
    }

    #[test]
    fn the_bridge_reads_commands_and_publishes_no_cmd_vel() {
        let g = Role::Bridge.grant();
        assert!(g.subscribe.contains(&"rt/*/cmd_vel".to_string()));
        assert!(!g.publish.iter().any(|t| t.contains("cmd_vel")));
        assert!(g.publish.contains(&"rt/clock".to_string()));
    }

    #[test]
    fn roles_parse_and_bad_ones_name_the_input() {
        assert_eq!(Role::parse("bridge"), Ok(Role::Bridge));
        assert_eq!(
            Role::parse("robots:robot_0, robot_1"),
            Ok(Role::Robots(vec!["robot_0".into(), "robot_1".into()]))
        );
        let e = Role::parse("robots:robot_*").unwrap_err();
        assert!(e.contains("robot_*"), "{e}");
        let e = Role::parse("admin").unwrap_err();
        assert!(e.contains("admin"), "{e}");
    }
}
