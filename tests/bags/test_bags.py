"""Bags written by `tending` (bag crate) read by third-party tools: rosbags (AnyReader, on the
.mcap file and on the bag directory) and mcap + mcap-ros2-support; recorders stopped by
SIGINT/SIGTERM leave complete bags, a SIGKILLed one leaves a file `tending bag recover`
turns into a bag holding everything up to its last complete chunk; `tending record`
records what `tending bag play` republishes over DDS.

The bags come from the hidden `tending bag synth` (a scripted episode on the contract
topics; with --realtime it paces itself at 10 Hz and finalizes on SIGINT/SIGTERM through
the same BagWriter path as `tending record`).
"""

import math
import os
import pathlib
import signal
import subprocess
import time

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML

from conftest import next_domain_id, run

MACHINES = [(-0.8, 0.8), (0.8, 0.8)]
STORAGES = [(0.0, -0.9)]
LEG = 15


def expected_pose(i, step):
    """Robot i's position at `step` in `bag synth` (shuttle machine <-> storage)."""
    m = MACHINES[i % len(MACHINES)]
    s = STORAGES[i % len(STORAGES)]
    phase = step % (2 * LEG)
    carrying = phase >= LEG
    f = (phase % LEG) / LEG
    a, b = (m, s) if carrying else (s, m)
    return a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f + 0.05 * i, carrying


def expected_counts(steps, robots):
    c = {'/clock': steps, '/tending/metrics': math.ceil(steps / 10), '/storage_0/pose': 1}
    for j in range(len(MACHINES)):
        c[f'/machine_{j}/pose'] = 1
        c[f'/machine_{j}/part_ready'] = math.ceil(steps / 5)
    for i in range(robots):
        for leaf in ('pose', 'has_part', 'cmd_vel'):
            c[f'/robot_{i}/{leaf}'] = steps
    return c


def stamp_ns(t):
    return t.sec * 1_000_000_000 + t.nanosec


def read_rosbags(path):
    """All messages of a bag via rosbags AnyReader: {topic: [(log_time, msg)]}, types."""
    out, types = {}, {}
    with AnyReader([pathlib.Path(path)]) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
            types[conn.topic] = conn.msgtype
    return out, types


def check_episode(msgs, robots, steps=None):
    """Values of a (possibly shortened) synth episode; returns the number of steps seen."""
    clock = [stamp_ns(m.clock) for _, m in msgs['/clock']]
    n = len(clock) if steps is None else steps
    assert clock == [round(k * 1e8) for k in range(len(clock))], 'clock not contiguous'
    for i in range(robots):
        poses = msgs.get(f'/robot_{i}/pose', [])
        flags = msgs.get(f'/robot_{i}/has_part', [])
        assert len(poses) in (n, n - 1) and len(flags) in (n, n - 1)
        for k, ((_, p), (_, h)) in enumerate(zip(poses, flags)):
            x, y, carrying = expected_pose(i, k)
            assert p.header.frame_id == 'map'
            assert p.header.stamp.sec * 1e9 + p.header.stamp.nanosec == pytest.approx(k * 1e8, abs=1)
            assert p.pose.position.x == pytest.approx(x, abs=1e-12)
            assert p.pose.position.y == pytest.approx(y, abs=1e-12)
            assert p.pose.orientation.w == 1.0
            assert h.data == carrying
    m0 = msgs['/machine_0/pose'][0][1].pose.position
    assert (m0.x, m0.y) == MACHINES[0]
    return len(clock)


@pytest.fixture
def synth_bag(tending, tmp_path):
    steps, robots = 80, 3
    d = tmp_path / 'episode'
    run(tending, 'bag', 'synth', d, '--duration', steps / 10, '--robots', robots)
    return d, steps, robots


def test_rosbags_reads_file_and_directory(synth_bag):
    d, steps, robots = synth_bag
    files = list(d.glob('*.mcap'))
    assert [f.name for f in files] == ['episode_0.mcap']
    for path in (d, files[0]):
        msgs, types = read_rosbags(path)
        assert {t: len(v) for t, v in msgs.items()} == expected_counts(steps, robots), path
        assert types['/robot_0/pose'] == 'geometry_msgs/msg/PoseStamped'
        assert types['/clock'] == 'rosgraph_msgs/msg/Clock'
        assert types['/tending/metrics'] == 'diagnostic_msgs/msg/DiagnosticArray'
        assert check_episode(msgs, robots, steps) == steps
        last = msgs['/tending/metrics'][-1][1].status[0]
        kv = {x.key: x.value for x in last.values}
        assert kv['robots'] == str(robots) and kv['step'] == str(steps - 10)
        # log times are nanoseconds, 100 ms apart
        times = [t for t, _ in msgs['/clock']]
        assert all(b - a == 100_000_000 for a, b in zip(times, times[1:]))


def test_rosbags_directory_qos_matches_channel(synth_bag):
    """metadata.yaml's offered_qos_profiles is the channel's string (rosbags pairs them)."""
    d, _, _ = synth_bag
    meta = YAML(typ='safe').load((d / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['version'] == 9 and meta['storage_identifier'] == 'mcap'
    with open(d / 'episode_0.mcap', 'rb') as f:
        summary = make_reader(f).get_summary()
    chan = {c.topic: c.metadata['offered_qos_profiles'] for c in summary.channels.values()}
    for t in meta['topics_with_message_count']:
        tm = t['topic_metadata']
        assert tm['offered_qos_profiles'] == chan[tm['name']], tm['name']
        assert tm['serialization_format'] == 'cdr'
    assert 'durability: transient_local' in chan['/machine_0/part_ready']
    assert 'reliability: reliable' in chan['/robot_1/cmd_vel']
    assert meta['message_count'] == summary.statistics.message_count


def test_mcap_ros2_decoder_reads_values(synth_bag):
    d, steps, robots = synth_bag
    with open(d / 'episode_0.mcap', 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        assert header.profile == 'ros2'
        summary = reader.get_summary()
        assert summary.statistics.message_count == sum(expected_counts(steps, robots).values())
        assert summary.statistics.chunk_count >= 7  # chunks close every second of data
        assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
        assert {c.message_encoding for c in summary.channels.values()} == {'cdr'}
        got = {}
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            got.setdefault(channel.topic, []).append((message.log_time, decoded))
            assert message.data[:4] == b'\x00\x01\x00\x00'
    assert {t: len(v) for t, v in got.items()} == expected_counts(steps, robots)
    for k, (_, tw) in enumerate(got['/robot_2/cmd_vel'][:5]):
        assert tw.angular.z == 0.0
    for k, (_, p) in enumerate(got['/robot_1/pose']):
        x, y, _ = expected_pose(1, k)
        assert (p.pose.position.x, p.pose.position.y) == (pytest.approx(x), pytest.approx(y))
    ready = [m.data for _, m in got['/machine_1/part_ready']]
    assert ready == [(5 * k) % (2 * LEG) < LEG for k in range(len(ready))]


def test_bag_cli_info_and_metrics(tending, synth_bag):
    d, steps, robots = synth_bag
    out = run(tending, 'bag', 'info', d)
    assert 'complete:  yes' in out and f'messages:  {sum(expected_counts(steps, robots).values())}' in out
    out = run(tending, 'bag', 'metrics', d)
    # 80 steps: robots pick at steps 15, 45, 75 and deliver at 30, 60
    assert f'total from has_part: {2 * robots} delivered, {3 * robots} picked' in out
    # the last /tending/metrics (step 70) predates the picks at step 75
    assert f'total from /tending/metrics: {2 * robots} delivered, {2 * robots} collected' in out


def start_realtime(tending, d, robots=2):
    return subprocess.Popen(
        [str(tending), 'bag', 'synth', str(d), '--duration', '60', '--robots', str(robots),
         '--realtime'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_stopped_recorder_leaves_complete_bag(tending, tmp_path, sig):
    d = tmp_path / 'stopped'
    p = start_realtime(tending, d)
    time.sleep(3.0)
    p.send_signal(sig)
    out, _ = p.communicate(timeout=20)
    assert p.returncode == 0, out
    msgs, _ = read_rosbags(d)  # the directory, as is: complete
    n = check_episode(msgs, robots=2)
    assert 20 <= n <= 40, n
    with open(next(d.glob('*.mcap')), 'rb') as f:
        assert make_reader(f).get_summary().statistics.message_count == sum(len(v) for v in msgs.values())


def test_sigkilled_recorder_recovers_up_to_last_chunk(tending, tmp_path):
    d = tmp_path / 'killed'
    p = start_realtime(tending, d)
    time.sleep(3.5)
    p.kill()
    p.wait(timeout=10)
    cut = next(d.glob('*.mcap'))
    with pytest.raises(Exception):  # no footer: third-party readers refuse the raw file
        read_rosbags(cut)
    info = run(tending, 'bag', 'info', d)
    assert 'complete:  NO' in info
    out_dir = tmp_path / 'recovered'
    rep = run(tending, 'bag', 'recover', d, out_dir)
    recovered = int(rep.split()[1])
    msgs, _ = read_rosbags(out_dir)
    assert sum(len(v) for v in msgs.values()) == recovered
    n = check_episode(msgs, robots=2)
    # chunks close every second (wall clock): at most ~1 s of the 3.5 s is lost
    assert 20 <= n <= 36, n
    # the provisional metadata.yaml of the killed bag counted exactly the closed chunks
    meta = YAML(typ='safe').load((d / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['message_count'] == recovered
    # the recovered file is complete for mcap too
    with open(next(out_dir.glob('*.mcap')), 'rb') as f:
        assert make_reader(f).get_summary().statistics.message_count == recovered


def test_record_what_play_publishes(tending, tmp_path):
    """`tending record` (discovery, contract QoS) records every message `bag play` sends."""
    src = tmp_path / 'src'
    steps, robots = 50, 2
    run(tending, 'bag', 'synth', src, '--duration', steps / 10, '--robots', robots)
    dom = str(next_domain_id())
    rec_dir = tmp_path / 'rec'
    rec = subprocess.Popen([str(tending), 'record', str(rec_dir), '--domain-id', dom],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        time.sleep(1.0)
        run(tending, 'bag', 'play', src, '--domain-id', dom, '--wait', '4', timeout=60)
        time.sleep(1.0)
    finally:
        rec.send_signal(signal.SIGINT)
        out, _ = rec.communicate(timeout=30)
    assert rec.returncode == 0, out
    got, types = read_rosbags(rec_dir)
    assert {t: len(v) for t, v in got.items()} == expected_counts(steps, robots), out
    assert types['/robot_1/has_part'] == 'std_msgs/msg/Bool'
    check_episode(got, robots, steps)
    meta = YAML(typ='safe').load((rec_dir / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    qos = {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles']
           for t in meta['topics_with_message_count']}
    assert 'durability: transient_local' in qos['/storage_0/pose']
    assert 'depth: 1\n' in qos['/clock']
