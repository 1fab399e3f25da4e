//! rosbag2 `metadata.yaml` (version 9, as Jazzy writes it; `rosbags` reads up to 9).
//!
//! `offered_qos_profiles` is a YAML *string* in this version (rosbag2 decodes it with
//! `as<std::string>()`), and it must be the same string as the MCAP channel's metadata:
//! `rosbags` pairs the topics of metadata.yaml with the channels of the file by topic, type
//! and parsed QoS, and silently yields nothing for a topic whose QoS differs.

use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

/// One topic of a bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    pub name: String,
    /// `pkg/msg/Type`
    pub type_name: String,
    /// The rosbag2 `offered_qos_profiles` YAML string.
    pub qos_yaml: String,
    pub message_count: u64,
}

/// What `metadata.yaml` says about a bag of one storage file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagMetadata {
    /// File name of the storage file, relative to the bag directory.
    pub file: String,
    pub topics: Vec<TopicInfo>,
    /// First and last message log time (ns since the epoch); `None` when empty.
    pub time_range: Option<(u64, u64)>,
    pub message_count: u64,
}

#[derive(Serialize, Deserialize)]
struct Root {
    rosbag2_bagfile_information: Info,
}

#[derive(Serialize, Deserialize)]
struct Nanos {
    nanoseconds: u64,
}

#[derive(Serialize, Deserialize)]
struct Since {
    nanoseconds_since_epoch: u64,
}

#[derive(Serialize, Deserialize)]
struct TopicMeta {
    name: String,
    #[serde(rename = "type")]
    type_: String,
    serialization_format: String,
    offered_qos_profiles: String,
    #[serde(default)]
    type_description_hash: String,
}

#[derive(Serialize, Deserialize)]
struct TopicWithCount {
    topic_metadata: TopicMeta,
    message_count: u64,
}

#[derive(Serialize, Deserialize)]
struct FileInfo {
    path: String,
    starting_time: Since,
    duration: Nanos,
    message_count: u64,
}

#[derive(Serialize, Deserialize)]
struct Info {
    version: u32,
    storage_identifier: String,
    duration: Nanos,
    starting_time: Since,
    message_count: u64,
    topics_with_message_count: Vec<TopicWithCount>,
    compression_format: String,
    compression_mode: String,
    relative_file_paths: Vec<String>,
    #[serde(default)]
    files: Vec<FileInfo>,
    #[serde(default)]
    custom_data: Option<std::collections::BTreeMap<String, String>>,
    #[serde(default)]
    ros_distro: String,
}

impl BagMetadata {
    /// The YAML text of `metadata.yaml`.
    pub fn to_yaml(&self) -> String {
        let (start, dur) = match self.time_range {
            Some((a, b)) => (a, b.saturating_sub(a)),
            None => (0, 0),
        };
        let root = Root {
            rosbag2_bagfile_information: Info {
                version: 9,
                storage_identifier: "mcap".into(),
                duration: Nanos { nanoseconds: dur },
                starting_time: Since {
                    nanoseconds_since_epoch: start,
                },
                message_count: self.message_count,
                topics_with_message_count: self
                    .topics
                    .iter()
                    .map(|t| TopicWithCount {
                        topic_metadata: TopicMeta {
                            name: t.name.clone(),
                            type_: t.type_name.clone(),
                            serialization_format: "cdr".into(),
                            offered_qos_profiles: t.qos_yaml.clone(),
                            type_description_hash: String::new(),
                        },
                        message_count: t.message_count,
                    })
                    .collect(),
                compression_format: String::new(),
                compression_mode: String::new(),
                relative_file_paths: vec![self.file.clone()],
                files: vec![FileInfo {
                    path: self.file.clone(),
                    starting_time: Since {
                        nanoseconds_since_epoch: start,
                    },
                    duration: Nanos { nanoseconds: dur },
                    message_count: self.message_count,
                }],
                custom_data: None,
                ros_distro: "jazzy".into(),
            },
        };
        serde_yaml::to_string(&root).expect("metadata serializes")
    }

    /// Parse a `metadata.yaml` text (only the fields this crate uses).
    pub fn from_yaml(text: &str) -> Result<Self> {
        let root: Root = serde_yaml::from_str(text).context("metadata.yaml")?;
        let i = root.rosbag2_bagfile_information;
        anyhow::ensure!(
            i.storage_identifier == "mcap",
            "storage `{}` is not mcap",
            i.storage_identifier
        );
        let file = i
            .relative_file_paths
            .first()
            .cloned()
            .context("metadata.yaml lists no storage file")?;
        let time_range = (i.message_count > 0).then(|| {
            (
                i.starting_time.nanoseconds_since_epoch,
                i.starting_time.nanoseconds_since_epoch + i.duration.nanoseconds,
            )
        });
        Ok(Self {
            file,
            topics: i
                .topics_with_message_count
                .into_iter()
                .map(|t| TopicInfo {
                    name: t.topic_metadata.name,
                    type_name: t.topic_metadata.type_,
                    qos_yaml: t.topic_metadata.offered_qos_profiles,
                    message_count: t.message_count,
                })
                .collect(),
            time_range,
            message_count: i.message_count,
        })
    }

    /// Write `dir/metadata.yaml` atomically (temporary file, then rename), so a reader or a
    /// kill never sees half a file.
    pub fn write_to(&self, dir: &Path) -> Result<()> {
        let tmp = dir.join(".metadata.yaml.tmp");
        std::fs::write(&tmp, self.to_yaml()).with_context(|| format!("{}", tmp.display()))?;
        std::fs::rename(&tmp, dir.join("metadata.yaml"))
            .with_context(|| format!("{}/metadata.yaml", dir.display()))?;
        Ok(())
    }

    pub fn read_from(dir: &Path) -> Result<Self> {
        let p = dir.join("metadata.yaml");
        let text = std::fs::read_to_string(&p).with_context(|| format!("{}", p.display()))?;
        Self::from_yaml(&text).with_context(|| format!("{}", p.display()))
    }
}
