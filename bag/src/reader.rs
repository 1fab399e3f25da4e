//! Reading bags (ours and other rosbag2 MCAP bags, uncompressed chunks) and recovering
//! bags cut by a killed recorder.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use mcap::records::{op, Record};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::metadata::BagMetadata;
use crate::writer::BagWriter;

/// One topic (MCAP channel) of a bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicSummary {
    pub name: String,
    /// `pkg/msg/Type` (the schema name)
    pub type_name: String,
    /// `ros2msg` schema text
    pub schema_text: String,
    /// `offered_qos_profiles` of the channel metadata (empty if absent)
    pub qos_yaml: String,
    pub message_count: u64,
}

/// One message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagMessage {
    /// Index into [`BagReader::topics`].
    pub topic_index: usize,
    pub log_time: u64,
    pub publish_time: u64,
    /// CDR with its encapsulation header.
    pub data: Vec<u8>,
}

/// A whole bag read into memory, in file order.
#[derive(Debug)]
pub struct BagReader {
    /// The MCAP file read.
    pub path: PathBuf,
    pub topics: Vec<TopicSummary>,
    pub messages: Vec<BagMessage>,
    /// True when the file ended with its data-end record, summary and footer.
    pub complete: bool,
    /// Why reading stopped early, for a cut or damaged file (messages up to there are kept).
    pub stopped_early: Option<String>,
}

impl BagReader {
    /// Read a bag directory (its `metadata.yaml`, or its only `.mcap` file) or an `.mcap`
    /// file. A file cut short is read up to its last complete chunk; see
    /// [`complete`](Self::complete) and [`stopped_early`](Self::stopped_early).
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let file = resolve_mcap(path.as_ref())?;
        let bytes = std::fs::read(&file).with_context(|| format!("read {}", file.display()))?;
        let mut r = Self::from_bytes(&bytes)
            .with_context(|| format!("read MCAP file {}", file.display()))?;
        r.path = file;
        Ok(r)
    }

    /// [`open`](Self::open), but a file that is not complete is an error.
    pub fn open_strict(path: impl AsRef<Path>) -> Result<Self> {
        let r = Self::open(path)?;
        if !r.complete {
            bail!(
                "{} is not a complete MCAP file ({}); `tending bag recover` rewrites it",
                r.path.display(),
                r.stopped_early.as_deref().unwrap_or("no footer")
            );
        }
        Ok(r)
    }

    /// Parse an MCAP file held in memory.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        if bytes.len() < mcap::MAGIC.len() || &bytes[..mcap::MAGIC.len()] != mcap::MAGIC {
            bail!("not an MCAP file (bad magic)");
        }
        let mut reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_skip_end_magic(true)
                .with_prevalidate_chunk_crcs(true)
                .with_record_length_limit(bytes.len()),
        );
        let mut schemas: HashMap<u16, (String, String)> = HashMap::new();
        let mut channels: HashMap<u16, usize> = HashMap::new();
        let mut out = Self {
            path: PathBuf::new(),
            topics: Vec::new(),
            messages: Vec::new(),
            complete: false,
            stopped_early: None,
        };
        let mut pos = 0usize;
        let mut data_end = false;
        let mut profile_ok = None;
        while let Some(ev) = reader.next_event() {
            let ev = match ev {
                Ok(ev) => ev,
                Err(e) => {
                    out.stopped_early = Some(format!("{e} at byte {pos} of {}", bytes.len()));
                    break;
                }
            };
            match ev {
                LinearReadEvent::ReadRequest(n) => {
                    let n = n.min(bytes.len() - pos);
                    reader.insert(n).copy_from_slice(&bytes[pos..pos + n]);
                    reader.notify_read(n);
                    pos += n;
                }
                LinearReadEvent::Record { data, opcode } => {
                    if opcode == op::DATA_END {
                        data_end = true;
                        break;
                    }
                    let rec = match mcap::parse_record(opcode, data) {
                        Ok(r) => r,
                        Err(e) => {
                            out.stopped_early = Some(format!("bad record {opcode:#04x}: {e}"));
                            break;
                        }
                    };
                    match rec {
                        Record::Header(h) => profile_ok = Some(h.profile == "ros2"),
                        Record::Schema { header, data } => {
                            schemas.insert(
                                header.id,
                                (header.name, String::from_utf8_lossy(&data).into_owned()),
                            );
                        }
                        Record::Channel(c) => {
                            if channels.contains_key(&c.id) {
                                continue;
                            }
                            let (type_name, schema_text) =
                                schemas.get(&c.schema_id).cloned().unwrap_or_default();
                            channels.insert(c.id, out.topics.len());
                            out.topics.push(TopicSummary {
                                name: c.topic,
                                type_name,
                                schema_text,
                                qos_yaml: c
                                    .metadata
                                    .get("offered_qos_profiles")
                                    .cloned()
                                    .unwrap_or_default(),
                                message_count: 0,
                            });
                        }
                        Record::Message { header, data } => {
                            let Some(&ti) = channels.get(&header.channel_id) else {
                                out.stopped_early = Some(format!(
                                    "message on unknown channel {}",
                                    header.channel_id
                                ));
                                break;
                            };
                            out.topics[ti].message_count += 1;
                            out.messages.push(BagMessage {
                                topic_index: ti,
                                log_time: header.log_time,
                                publish_time: header.publish_time,
                                data: data.into_owned(),
                            });
                        }
                        _ => {}
                    }
                }
            }
        }
        if profile_ok == Some(false) {
            bail!("MCAP profile is not ros2");
        }
        // Complete = data end reached and a valid footer + summary at the end.
        out.complete = data_end && mcap::read::footer(bytes).is_ok();
        if !out.complete && out.stopped_early.is_none() {
            out.stopped_early = Some(if data_end {
                "no valid footer".into()
            } else {
                format!("file ends after {} bytes without data end", bytes.len())
            });
        }
        Ok(out)
    }

    pub fn topic(&self, m: &BagMessage) -> &TopicSummary {
        &self.topics[m.topic_index]
    }

    /// The index of a topic by name.
    pub fn topic_index(&self, name: &str) -> Option<usize> {
        self.topics.iter().position(|t| t.name == name)
    }

    /// First and last log time.
    pub fn time_range(&self) -> Option<(u64, u64)> {
        let a = self.messages.iter().map(|m| m.log_time).min()?;
        let b = self.messages.iter().map(|m| m.log_time).max()?;
        Some((a, b))
    }

    /// Decode the messages of one topic (CDR with header) into `M`, with their log times.
    pub fn decode_topic<M: msgs::RosMessage>(&self, name: &str) -> Result<Vec<(u64, M)>> {
        let Some(ti) = self.topic_index(name) else {
            return Ok(Vec::new());
        };
        self.messages
            .iter()
            .filter(|m| m.topic_index == ti)
            .map(|m| {
                msgs::cdr::decode::<M>(&m.data)
                    .map(|v| (m.log_time, v))
                    .map_err(|e| anyhow::anyhow!("{name}: {e}"))
            })
            .collect()
    }
}

/// The MCAP file of `path`: the file itself, or the one `metadata.yaml` names in a
/// directory, or a directory's only `.mcap` file.
fn resolve_mcap(path: &Path) -> Result<PathBuf> {
    if !path.is_dir() {
        if !path.exists() {
            bail!("{} does not exist", path.display());
        }
        return Ok(path.to_path_buf());
    }
    if path.join("metadata.yaml").exists() {
        if let Ok(m) = BagMetadata::read_from(path) {
            let f = path.join(&m.file);
            if f.exists() {
                return Ok(f);
            }
        }
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(path)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    found.sort();
    match found.len() {
        0 => bail!("{} holds no .mcap file", path.display()),
        1 => Ok(found.remove(0)),
        _ => bail!(
            "{} holds {} .mcap files and no usable metadata.yaml",
            path.display(),
            found.len()
        ),
    }
}

/// What [`recover`] did.
#[derive(Debug, Clone)]
pub struct RecoverReport {
    pub input: PathBuf,
    pub messages: u64,
    pub topics: usize,
    pub input_was_complete: bool,
    pub stopped_early: Option<String>,
    pub time_range: Option<(u64, u64)>,
}

/// Rewrite the bag `input` (a file or directory, possibly cut by SIGKILL: no summary, no
/// footer, maybe half a chunk) into the new complete bag directory `out` holding every
/// message of every complete chunk, with the original topics, types, schemas, QoS and
/// times.
pub fn recover(input: impl AsRef<Path>, out: impl AsRef<Path>) -> Result<RecoverReport> {
    let r = BagReader::open(input.as_ref())?;
    let mut w = BagWriter::create(out.as_ref())?;
    for t in &r.topics {
        if t.type_name.is_empty() {
            bail!("topic {} has no schema in {}", t.name, r.path.display());
        }
        w.add_topic_raw(&t.name, &t.type_name, &t.schema_text, &t.qos_yaml)?;
    }
    for m in &r.messages {
        w.write_full(
            &r.topics[m.topic_index].name,
            m.log_time,
            m.publish_time,
            &m.data,
        )?;
    }
    w.finish()?;
    Ok(RecoverReport {
        input: r.path.clone(),
        messages: r.messages.len() as u64,
        topics: r.topics.len(),
        input_was_complete: r.complete,
        stopped_early: r.stopped_early.clone(),
        time_range: r.time_range(),
    })
}
