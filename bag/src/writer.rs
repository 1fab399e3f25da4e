//! The bag writer: rosbag2-compatible MCAP plus `metadata.yaml`.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use msgs::{MsgDef, RosMessage};

use crate::metadata::{BagMetadata, TopicInfo};

/// When a chunk is closed (written to the file). A chunk is held in memory until then, so
/// these bound what a SIGKILL can lose.
#[derive(Debug, Clone, Copy)]
pub struct WriterOptions {
    /// Close the chunk once its uncompressed content reaches this many bytes.
    pub chunk_bytes: u64,
    /// Close the chunk before a message whose log time is this far past the chunk's first.
    pub chunk_span_ns: u64,
    /// Close the chunk once it has been open this long (wall clock), checked on every write
    /// and on [`BagWriter::flush_due`].
    pub chunk_wall: Duration,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            chunk_bytes: 1 << 20,
            chunk_span_ns: 1_000_000_000,
            chunk_wall: Duration::from_secs(1),
        }
    }
}

struct Topic {
    info: TopicInfo,
    channel_id: u16,
    sequence: u32,
    /// Messages of this topic already in closed chunks.
    flushed: u64,
}

struct OpenChunk {
    bytes: u64,
    messages: u64,
    first_log: u64,
    opened: Instant,
}

/// Writes one rosbag2 MCAP bag directory. Dropping it finalizes the bag (errors are then
/// ignored; call [`finish`](Self::finish) to see them).
pub struct BagWriter {
    dir: PathBuf,
    file: String,
    mcap: Option<mcap::Writer<BufWriter<File>>>,
    opts: WriterOptions,
    schemas: HashMap<String, u16>,
    topics: Vec<Topic>,
    by_name: HashMap<String, usize>,
    chunk: Option<OpenChunk>,
    /// Log-time range of all messages written / of those in closed chunks.
    range: Option<(u64, u64)>,
    flushed_range: Option<(u64, u64)>,
}

fn widen(r: Option<(u64, u64)>, t: u64) -> Option<(u64, u64)> {
    Some(match r {
        None => (t, t),
        Some((a, b)) => (a.min(t), b.max(t)),
    })
}

impl BagWriter {
    /// Create the bag directory `dir` (it must not exist, or be empty) with default chunking.
    pub fn create(dir: impl AsRef<Path>) -> Result<Self> {
        Self::create_with(dir, WriterOptions::default())
    }

    pub fn create_with(dir: impl AsRef<Path>, opts: WriterOptions) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        if dir.exists() {
            let non_empty = std::fs::read_dir(&dir)
                .with_context(|| format!("bag directory {}", dir.display()))?
                .next()
                .is_some();
            if non_empty {
                bail!(
                    "bag directory {} already exists and is not empty",
                    dir.display()
                );
            }
        }
        std::fs::create_dir_all(&dir).with_context(|| format!("create {}", dir.display()))?;
        let file = crate::mcap_file_name(&dir);
        let f = File::create(dir.join(&file))
            .with_context(|| format!("create {}", dir.join(&file).display()))?;
        // Buffered chunks (disable_seeking): a chunk reaches the file whole when it is
        // closed, so a killed writer leaves complete chunks followed by at most one cut
        // record. No compression: the C codecs stay out of the build.
        let options = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("tending-bag-", env!("CARGO_PKG_VERSION")))
            .compression(None)
            .use_chunks(true)
            .chunk_size(None)
            .disable_seeking(true);
        let mcap = options
            .create(BufWriter::with_capacity(1 << 16, f))
            .context("write MCAP header")?;
        let w = Self {
            dir,
            file,
            mcap: Some(mcap),
            opts,
            schemas: HashMap::new(),
            topics: Vec::new(),
            by_name: HashMap::new(),
            chunk: None,
            range: None,
            flushed_range: None,
        };
        // The header reaches the disk now, and a provisional metadata.yaml describes it.
        w.provisional_metadata().write_to(&w.dir)?;
        Ok(w)
    }

    /// The bag directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The MCAP storage file.
    pub fn mcap_path(&self) -> PathBuf {
        self.dir.join(&self.file)
    }

    pub fn has_topic(&self, name: &str) -> bool {
        self.by_name.contains_key(name)
    }

    /// Add a topic of a wire type; `qos_yaml` is the rosbag2 `offered_qos_profiles` string
    /// (`msgs::Profile::offered_qos_yaml()`). Adding the same topic again with the same type
    /// is a no-op; with another type it is an error.
    pub fn add_topic(&mut self, name: &str, def: &MsgDef, qos_yaml: &str) -> Result<()> {
        self.add_topic_raw(name, &def.full_name(), &msgs::schema_text(def), qos_yaml)
    }

    /// Add a topic from its type name (`pkg/msg/Type`) and `ros2msg` schema text.
    pub fn add_topic_raw(
        &mut self,
        name: &str,
        type_name: &str,
        schema_text: &str,
        qos_yaml: &str,
    ) -> Result<()> {
        if let Some(&i) = self.by_name.get(name) {
            let t = &self.topics[i].info;
            if t.type_name != type_name {
                bail!(
                    "topic {name} is already in the bag as {}, not {type_name}",
                    t.type_name
                );
            }
            return Ok(());
        }
        let mcap = self.mcap.as_mut().context("bag already finished")?;
        let schema_id = match self.schemas.get(type_name) {
            Some(&id) => id,
            None => {
                let id = mcap
                    .add_schema(type_name, "ros2msg", schema_text.as_bytes())
                    .with_context(|| format!("add schema {type_name}"))?;
                self.schemas.insert(type_name.to_string(), id);
                id
            }
        };
        let mut meta = BTreeMap::new();
        meta.insert("offered_qos_profiles".to_string(), qos_yaml.to_string());
        let channel_id = mcap
            .add_channel(schema_id, name, "cdr", &meta)
            .with_context(|| format!("add channel {name}"))?;
        let added = (schema_text.len() + qos_yaml.len() + name.len() + 64) as u64;
        self.open_chunk(None).bytes += added;
        self.by_name.insert(name.to_string(), self.topics.len());
        self.topics.push(Topic {
            info: TopicInfo {
                name: name.to_string(),
                type_name: type_name.to_string(),
                qos_yaml: qos_yaml.to_string(),
                message_count: 0,
            },
            channel_id,
            sequence: 0,
            flushed: 0,
        });
        Ok(())
    }

    fn open_chunk(&mut self, log_time: Option<u64>) -> &mut OpenChunk {
        let c = self.chunk.get_or_insert_with(|| OpenChunk {
            bytes: 0,
            messages: 0,
            first_log: log_time.unwrap_or(u64::MAX),
            opened: Instant::now(),
        });
        if let Some(t) = log_time {
            c.first_log = c.first_log.min(t);
        }
        c
    }

    /// Write one message: `cdr` is the serialized message *with* its 4-byte encapsulation
    /// header; `time_ns` is its log and publish time (ns since the epoch, or sim time).
    pub fn write(&mut self, topic: &str, time_ns: u64, cdr: &[u8]) -> Result<()> {
        self.write_full(topic, time_ns, time_ns, cdr)
    }

    /// Encode `msg` (CDR with header) and write it.
    pub fn write_msg<M: RosMessage>(&mut self, topic: &str, time_ns: u64, msg: &M) -> Result<()> {
        let bytes = msgs::cdr::encode(msg).map_err(|e| anyhow::anyhow!("{topic}: {e}"))?;
        self.write(topic, time_ns, &bytes)
    }

    /// Write `msg` on a contract topic (see [`crate::contract_topic`]), adding the topic with
    /// its contract type and QoS on first use: the one call a publisher needs to record what
    /// it publishes. A type other than the contract's is an error.
    pub fn write_contract<M: RosMessage>(
        &mut self,
        topic: &str,
        time_ns: u64,
        msg: &M,
    ) -> Result<()> {
        if !self.has_topic(topic) {
            let (name, def, profile) = crate::contract_topic(topic)
                .with_context(|| format!("{topic} is not a contract topic"))?;
            if !std::ptr::eq(def, M::DEF) {
                bail!(
                    "{topic} carries {} in the contract, not {}",
                    def.full_name(),
                    M::DEF.full_name()
                );
            }
            self.add_topic(&name, def, &profile.offered_qos_yaml())?;
        }
        self.write_msg(topic, time_ns, msg)
    }

    /// [`write`](Self::write) with distinct log and publish times.
    pub fn write_full(
        &mut self,
        topic: &str,
        log_time: u64,
        publish_time: u64,
        cdr: &[u8],
    ) -> Result<()> {
        let &i = self
            .by_name
            .get(topic)
            .with_context(|| format!("topic {topic} was not added to the bag"))?;
        if cdr.len() < 4 || cdr[0] != 0 || cdr[1] > 1 {
            bail!("{topic}: message is not CDR with an encapsulation header (00 00 / 00 01 ...)");
        }
        // Close the open chunk first if this message would make it span too long or grow
        // too big.
        if let Some(c) = &self.chunk {
            if c.messages > 0
                && (log_time.saturating_sub(c.first_log) >= self.opts.chunk_span_ns
                    || c.bytes + cdr.len() as u64 > self.opts.chunk_bytes)
            {
                self.flush()?;
            }
        }
        let t = &mut self.topics[i];
        let header = mcap::records::MessageHeader {
            channel_id: t.channel_id,
            sequence: t.sequence,
            log_time,
            publish_time,
        };
        t.sequence = t.sequence.wrapping_add(1);
        t.info.message_count += 1;
        self.mcap
            .as_mut()
            .context("bag already finished")?
            .write_to_known_channel(&header, cdr)
            .with_context(|| format!("write message on {topic}"))?;
        self.range = widen(self.range, log_time);
        let c = self.open_chunk(Some(log_time));
        c.messages += 1;
        c.bytes += cdr.len() as u64 + 31;
        self.flush_due()
    }

    /// Close the open chunk if it has been open longer than `chunk_wall` (call this
    /// periodically while no messages arrive, e.g. from a recorder's loop).
    pub fn flush_due(&mut self) -> Result<()> {
        let due = self
            .chunk
            .as_ref()
            .is_some_and(|c| c.messages > 0 && c.opened.elapsed() >= self.opts.chunk_wall);
        if due {
            self.flush()?;
        }
        Ok(())
    }

    /// Close the open chunk (write it and its message indexes), flush the file and rewrite
    /// the provisional `metadata.yaml` to describe what is now on disk.
    pub fn flush(&mut self) -> Result<()> {
        let Some(mcap) = self.mcap.as_mut() else {
            return Ok(());
        };
        if self.chunk.is_none() {
            return Ok(());
        }
        mcap.flush().context("write MCAP chunk")?;
        self.chunk = None;
        for t in &mut self.topics {
            t.flushed = t.info.message_count;
        }
        self.flushed_range = self.range;
        self.provisional_metadata().write_to(&self.dir)
    }

    fn metadata(&self, flushed_only: bool) -> BagMetadata {
        let topics: Vec<TopicInfo> = self
            .topics
            .iter()
            .map(|t| TopicInfo {
                message_count: if flushed_only {
                    t.flushed
                } else {
                    t.info.message_count
                },
                ..t.info.clone()
            })
            .collect();
        BagMetadata {
            file: self.file.clone(),
            message_count: topics.iter().map(|t| t.message_count).sum(),
            topics,
            time_range: if flushed_only {
                self.flushed_range
            } else {
                self.range
            },
        }
    }

    fn provisional_metadata(&self) -> BagMetadata {
        self.metadata(true)
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.topics.iter().map(|t| t.info.message_count).sum()
    }

    /// Close the last chunk, write the summary (schemas, channels, Statistics, chunk
    /// indexes) and footer, sync the file and write the final `metadata.yaml`.
    pub fn finish(mut self) -> Result<BagMetadata> {
        self.finish_inner()
    }

    fn finish_inner(&mut self) -> Result<BagMetadata> {
        let Some(mut mcap) = self.mcap.take() else {
            return Ok(self.metadata(false));
        };
        mcap.finish().context("write MCAP summary and footer")?;
        let mut buf = mcap.into_inner();
        buf.flush().context("flush MCAP file")?;
        let f = buf
            .into_inner()
            .map_err(|e| anyhow::anyhow!("flush MCAP file: {}", e.error()))?;
        f.sync_all().ok();
        self.chunk = None;
        let meta = self.metadata(false);
        meta.write_to(&self.dir)?;
        Ok(meta)
    }
}

impl Drop for BagWriter {
    fn drop(&mut self) {
        let _ = self.finish_inner();
    }
}
