"""sim_bridge (Rust, ros2-client/RustDDS) read and driven by real rclpy (Jazzy, Fast DDS).

One bridge (setup 6.4_2: 6 robots, 4 machines, 2 storages) for the whole module. rclpy plays
RViz / a robot: it subscribes to every contract topic with the contract QoS, checks types and
values, and publishes cmd_vel for a namespace the bridge has never seen.
"""

import math
import re

import pytest

from conftest import (
    CLOCK,
    DISCOVERY_TIMEOUT_S,
    LATCHED,
    ROBOT_STREAM,
    ROOM_HALF,
    SIM_BRIDGE,
    VISUALIZATION,
    Periodic,
    Proc,
    Ros,
    child_env,
    next_domain_id,
    require_binary,
)
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Bool
from visualization_msgs.msg import Marker, MarkerArray

N_ROBOTS, N_MACHINES, N_STORAGES = 6, 4, 2
EPS = 1e-6

TYPES = {
    'pose': 'geometry_msgs/msg/PoseStamped',
    'has_part': 'std_msgs/msg/Bool',
    'part_ready': 'std_msgs/msg/Bool',
    'cmd_vel': 'geometry_msgs/msg/Twist',
}
FIXED = {
    '/clock': 'rosgraph_msgs/msg/Clock',
    '/tending/markers': 'visualization_msgs/msg/MarkerArray',
    '/tending/metrics': 'diagnostic_msgs/msg/DiagnosticArray',
    '/rosout': 'rcl_interfaces/msg/Log',
    '/parameter_events': 'rcl_interfaces/msg/ParameterEvent',
}
ENTITY_TOPIC = re.compile(r'^/(robot_\d+|machine_\d+|storage_\d+)/(pose|has_part|part_ready)$')


def contract_type(topic):
    if topic in FIXED:
        return FIXED[topic]
    m = ENTITY_TOPIC.match(topic)
    return TYPES[m.group(2)] if m else None


def contract_durability(topic):
    if topic.startswith(('/machine_', '/storage_')):
        return DurabilityPolicy.TRANSIENT_LOCAL
    return DurabilityPolicy.VOLATILE


class Inbox:
    def __init__(self, ros, msg_type, topic, qos):
        self.msgs = []
        ros.node.create_subscription(msg_type, topic, self.msgs.append, qos)


class Bridge:
    def __init__(self, ros, proc):
        self.ros, self.proc = ros, proc
        self.inbox = {}

    def listen(self, msg_type, topic, qos):
        if topic not in self.inbox:
            self.inbox[topic] = Inbox(self.ros, msg_type, topic, qos)
        return self.inbox[topic]

    def rust_topics(self):
        """Topic -> types of every writer in the domain that is not rclpy's."""
        node = self.ros.node
        out = {}
        for topic, _ in node.get_topic_names_and_types():
            for ep in node.get_publishers_info_by_topic(topic):
                if ep.node_name != node.get_name():
                    out.setdefault(topic, set()).add(ep.topic_type)
        return out


def _names(topics, kind, leaf):
    rx = re.compile(rf'^/({kind}_\d+)/{leaf}$')
    return sorted(m.group(1) for t in topics if (m := rx.match(t)))


@pytest.fixture(scope='module')
def bridge(tmp_path_factory):
    require_binary(SIM_BRIDGE)
    d = next_domain_id()
    ros = Ros(d, 'bridge_test')
    # everything the contract says the bridge publishes, subscribed before it starts
    b = Bridge(ros, None)
    b.listen(Clock, '/clock', CLOCK)
    b.listen(MarkerArray, '/tending/markers', VISUALIZATION)
    b.listen(DiagnosticArray, '/tending/metrics', VISUALIZATION)
    for i in range(N_ROBOTS):
        b.listen(PoseStamped, f'/robot_{i}/pose', ROBOT_STREAM)
        b.listen(Bool, f'/robot_{i}/has_part', ROBOT_STREAM)
    log = tmp_path_factory.mktemp('bridge') / 'sim_bridge.log'
    # initial robots get no cmd_vel here: keep them past the default 10 s start-up grace
    b.proc = Proc([SIM_BRIDGE, '--ros-args', '-p', 'setup:=6.4_2', '-p', 'seed:=3',
                   '-p', 'startup_grace_s:=300', '-p', 'wait_for_robots:=false',
                   '-p', 'metrics_period_s:=0.5'],
                  log, child_env(d))
    try:
        ros.spin_until(lambda: len(_names(b.rust_topics(), 'machine', 'pose')) == N_MACHINES
                       and len(_names(b.rust_topics(), 'storage', 'pose')) == N_STORAGES,
                       DISCOVERY_TIMEOUT_S, 'machine and storage topics in the graph')
        topics = b.rust_topics()
        for name in _names(topics, 'machine', 'pose'):
            b.listen(PoseStamped, f'/{name}/pose', LATCHED)
            b.listen(Bool, f'/{name}/part_ready', LATCHED)
        for name in _names(topics, 'storage', 'pose'):
            b.listen(PoseStamped, f'/{name}/pose', LATCHED)
        ros.spin_until(lambda: all(i.msgs for i in b.inbox.values()), DISCOVERY_TIMEOUT_S,
                       'a sample on every contract topic: missing ' + ', '.join(
                           t for t, i in b.inbox.items() if not i.msgs))
        yield b
    finally:
        code = b.proc.terminate()
        ros.close()
        assert code == 0, f'sim_bridge exit code {code}; log:\n{b.proc.text()[-2000:]}'


def test_every_bridge_publication_has_the_contract_type(bridge):
    topics = bridge.rust_topics()
    for topic, types in topics.items():
        want = contract_type(topic)
        assert want is not None, f'publication outside the contract: {topic} {types}'
        assert types == {want}, f'{topic}: {types}, want {want}'
    assert _names(topics, 'robot', 'pose') == sorted(f'robot_{i}' for i in range(N_ROBOTS))
    assert _names(topics, 'robot', 'has_part') == _names(topics, 'robot', 'pose')
    assert _names(topics, 'machine', 'part_ready') == _names(topics, 'machine', 'pose')
    for t in ('/clock', '/tending/markers', '/tending/metrics'):
        assert t in topics, t


def test_clock_has_only_the_contract_type_in_the_graph(bridge):
    types = dict(bridge.ros.node.get_topic_names_and_types()).get('/clock')
    assert types == ['rosgraph_msgs/msg/Clock'], types


def test_every_bridge_writer_is_reliable_with_contract_durability(bridge):
    node = bridge.ros.node
    checked = 0
    for topic in bridge.rust_topics():
        if topic in ('/rosout', '/parameter_events'):
            continue
        for ep in node.get_publishers_info_by_topic(topic):
            if ep.node_name == node.get_name():
                continue
            q = ep.qos_profile
            assert q.reliability == ReliabilityPolicy.RELIABLE, f'{topic}: {q}'
            assert q.durability == contract_durability(topic), f'{topic}: {q}'
            checked += 1
    assert checked >= 3 + 2 * N_ROBOTS + 2 * N_MACHINES + N_STORAGES


def test_clock_advances(bridge):
    ros, inbox = bridge.ros, bridge.inbox['/clock']
    n0 = len(inbox.msgs)
    ros.spin_for(1.0)
    got = inbox.msgs[n0:]
    assert len(got) >= 4, f'{len(got)} /clock samples in 1 s (rate_hz 10)'
    t = [m.clock.sec + m.clock.nanosec * 1e-9 for m in inbox.msgs]
    assert all(math.isfinite(x) and x >= 0 for x in t)
    assert all(b > a for a, b in zip(t, t[1:])), 'sim time not strictly increasing'


def _xy(m):
    return m.pose.position.x, m.pose.position.y


def _inside(x, y):
    return (math.isfinite(x) and math.isfinite(y)
            and abs(x) <= ROOM_HALF + EPS and abs(y) <= ROOM_HALF + EPS)


def test_poses_and_flags_are_sane(bridge):
    poses = {t: i.msgs for t, i in bridge.inbox.items() if t.endswith('/pose')}
    assert len(poses) == N_ROBOTS + N_MACHINES + N_STORAGES
    last_clock = bridge.inbox['/clock'].msgs[-1].clock
    for topic, msgs in poses.items():
        for m in msgs:
            assert m.header.frame_id == 'map', topic
            assert _inside(*_xy(m)), f'{topic}: {_xy(m)} outside the room'
            q = m.pose.orientation
            assert abs(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2 - 1.0) < 1e-6, topic
            # stamped with sim time, never ahead of the latest /clock by more than a step
            st = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            assert st <= last_clock.sec + last_clock.nanosec * 1e-9 + 0.2, topic
    # boxes do not overlap each other's centres
    centres = [_xy(poses[t][-1]) for t in poses if not t.startswith('/robot_')]
    assert len({(round(x, 3), round(y, 3)) for x, y in centres}) == len(centres)
    flags = [i.msgs for t, i in bridge.inbox.items()
             if t.endswith(('/has_part', '/part_ready'))]
    assert len(flags) == N_ROBOTS + N_MACHINES and all(f for f in flags)


def test_metrics_are_finite_and_in_range(bridge):
    ros, inbox = bridge.ros, bridge.inbox['/tending/metrics']
    n0 = len(inbox.msgs)
    ros.spin_until(lambda: len(inbox.msgs) > n0, 5.0, 'a new /tending/metrics sample')
    arr = inbox.msgs[-1]
    [st] = [s for s in arr.status if s.name == 'tending/metrics']
    kv = {v.key: v.value for v in st.values}
    for k in ('parts_delivered', 'parts_collected', 'collisions', 'machine_utilization'):
        assert k in kv, f'{k} missing from {sorted(kv)}'
        assert math.isfinite(float(kv[k])) and float(kv[k]) >= 0, f'{k}={kv[k]}'
    assert 0.0 <= float(kv['machine_utilization']) <= 1.0
    assert int(kv['robots']) >= N_ROBOTS


def test_markers_show_every_body_inside_the_room(bridge):
    arr = bridge.inbox['/tending/markers'].msgs[-1]
    assert arr.markers[0].action == Marker.DELETEALL
    by_ns = {}
    for m in arr.markers[1:]:
        assert m.action == Marker.ADD
        assert m.header.frame_id == 'map'
        assert _inside(m.pose.position.x, m.pose.position.y), (m.ns, m.pose.position)
        assert m.scale.x > 0 and m.scale.y > 0 and m.color.a > 0
        by_ns[m.ns] = by_ns.get(m.ns, 0) + 1
    assert by_ns.get('machines') == N_MACHINES and by_ns.get('storages') == N_STORAGES, by_ns
    assert by_ns.get('robots', 0) >= N_ROBOTS, by_ns


def test_latched_topics_reach_a_late_subscriber(bridge):
    """Transient local from the Rust writers to a Fast DDS reader created now: the last
    machine/storage samples arrive without waiting for a new publication."""
    ros = bridge.ros
    late = []
    topics = [t for t in bridge.inbox if t.startswith(('/machine_', '/storage_'))]
    subs = [ros.node.create_subscription(PoseStamped if t.endswith('/pose') else Bool, t,
                                         lambda m, t=t: late.append(t), LATCHED)
            for t in topics]
    ros.spin_until(lambda: set(late) == set(topics), 5.0,
                   f'latched samples for a late subscriber (got {sorted(set(late))})')
    for s in subs:
        ros.node.destroy_subscription(s)


def test_cmd_vel_from_rclpy_spawns_and_moves_a_new_robot(bridge):
    """A cmd_vel stream on /robot_77 (a namespace the bridge has never seen) spawns a body:
    /robot_77/pose appears, the body moves the commanded way, reverses when the command
    does, and is removed when the commands stop (stale)."""
    ros = bridge.ros
    pose = bridge.listen(PoseStamped, '/robot_77/pose', ROBOT_STREAM)
    v = {'x': 0.0, 'y': 0.0}

    def twist():
        t = Twist()
        t.linear.x, t.linear.y = v['x'], v['y']
        return t
    cmd = Periodic(ros, Twist, '/robot_77/cmd_vel', ROBOT_STREAM, twist, hz=10)
    ros.spin_until(lambda: pose.msgs, DISCOVERY_TIMEOUT_S, '/robot_77/pose after its cmd_vel')
    x0, y0 = _xy(pose.msgs[-1])
    assert _inside(x0, y0)
    assert '/robot_77/pose' in bridge.rust_topics()
    # the axis direction with the longest free run (walls, boxes and robots as published)
    others = [_xy(i.msgs[-1]) for t, i in bridge.inbox.items()
              if t.endswith('/pose') and t != '/robot_77/pose' and i.msgs]
    axis, sign, free = max(((a, sg, _free_run((x0, y0), a, sg, others))
                            for a in (0, 1) for sg in (1.0, -1.0)), key=lambda c: c[2])
    assert free > 0.3, f'robot_77 spawned boxed in at ({x0:.2f}, {y0:.2f}): free run {free:.2f} m'

    def moved(seconds, s):
        v['xy'[axis]] = s * 0.3
        a = _xy(pose.msgs[-1])[axis]
        ros.spin_for(seconds)
        b = _xy(pose.msgs[-1])
        assert _inside(*b)
        return (b[axis] - a) * s
    d1 = moved(1.0, sign)
    assert d1 > 0.15, (f'moved {d1:.3f} m along {"xy"[axis]} when commanded {sign * 0.3} m/s '
                       f'for 1 s from ({x0:.2f}, {y0:.2f}), free run {free:.2f} m')
    d2 = moved(1.0, -sign)
    assert d2 > 0.15, f'moved {d2:.3f} m back after reversing the command'
    v['xy'[axis]] = 0.0
    ros.spin_for(0.5)
    a = _xy(pose.msgs[-1])
    ros.spin_for(0.5)
    b = _xy(pose.msgs[-1])
    assert math.dist(a, b) < 0.03, f'still moving at a zero command: {a} -> {b}'
    # commands stop: the body is removed after stale_timeout_s (2 s); its pose stops
    cmd.active = False
    ros.spin_until(lambda: _stopped(ros, pose, 1.0), 8.0, '/robot_77/pose to stop (despawn)')
    assert 'removed /robot_77' in bridge.proc.text()


def _free_run(p, axis, sign, others, clearance=0.3):
    """How far a body at p can go along axis (0 x, 1 y) in direction sign before coming
    within `clearance` of another body's centre or of a wall."""
    run = ROOM_HALF - sign * p[axis] - 0.1
    for c in others:
        along = (c[axis] - p[axis]) * sign
        lateral = abs(c[1 - axis] - p[1 - axis])
        if along > 0 and lateral < clearance:
            run = min(run, along - clearance)
    return run


def _stopped(ros, inbox, quiet_s):
    n = len(inbox.msgs)
    ros.spin_for(quiet_s)
    return len(inbox.msgs) == n


def test_robot_node_tends_in_the_bridge_watched_by_rclpy(tmp_path):
    """The production loop, Rust <-> Rust over DDS, observed by rclpy: sim_bridge plus one
    greedy robot_node for /robot_0 (default parameters, use_sim_time): robot_0 picks a part
    (has_part goes true) and delivers it (parts_delivered on /tending/metrics), while
    robot_1, without a node, stands still."""
    from conftest import ROBOT_NODE
    require_binary(SIM_BRIDGE)
    require_binary(ROBOT_NODE)
    d = next_domain_id()
    ros = Ros(d, 'fleet_test')
    poses = {i: Inbox(ros, PoseStamped, f'/robot_{i}/pose', ROBOT_STREAM) for i in (0, 1)}
    part = Inbox(ros, Bool, '/robot_0/has_part', ROBOT_STREAM)
    cmds = Inbox(ros, Twist, '/robot_0/cmd_vel', ROBOT_STREAM)
    metrics = Inbox(ros, DiagnosticArray, '/tending/metrics', VISUALIZATION)
    env = child_env(d)
    procs = [Proc([SIM_BRIDGE, '--ros-args', '-p', 'setup:=6.4_2', '-p', 'seed:=3',
                   '-p', 'startup_grace_s:=300', '-p', 'wait_for_robots:=false',
                   '-p', 'metrics_period_s:=0.5'],
                  tmp_path / 'sim_bridge.log', env),
             Proc([ROBOT_NODE, '--ros-args', '-r', '__ns:=/robot_0', '-p', 'use_sim_time:=true'],
                  tmp_path / 'robot_node.log', env)]

    def delivered():
        for arr in reversed(metrics.msgs):
            for st in arr.status:
                kv = {v.key: v.value for v in st.values}
                if 'parts_delivered' in kv:
                    return int(kv['parts_delivered'])
        return 0
    try:
        ros.spin_until(lambda: poses[0].msgs and poses[1].msgs, DISCOVERY_TIMEOUT_S,
                       'robot poses from the bridge')
        start1 = _xy(poses[1].msgs[0])
        ros.spin_until(lambda: any(m.data for m in part.msgs), 30.0,
                       'robot_0 picking a part (has_part true)')
        ros.spin_until(lambda: delivered() >= 1, 30.0,
                       'robot_0 delivering its part (parts_delivered >= 1)')
        path = sum(math.dist(_xy(a), _xy(b)) for a, b in zip(poses[0].msgs, poses[0].msgs[1:]))
        assert path > 0.1, f'robot_0 travelled {path:.3f} m'
        assert all(_inside(*_xy(m)) for m in poses[0].msgs)
        assert math.dist(start1, _xy(poses[1].msgs[-1])) < 0.15, 'robot_1 has no node'
        assert any(abs(m.linear.x) + abs(m.linear.y) > 0 for m in cmds.msgs)
    finally:
        codes = [p.terminate() for p in reversed(procs)]
        ros.close()
    assert codes == [0, 0], codes


def test_lockstep_stamps_are_readable_by_rclpy(tmp_path):
    """Lockstep (sim_bridge mode:=lockstep, robot_node lockstep:=true): samples without a
    header carry the simulator state's time as their DDS source timestamp. A stock rclpy
    subscriber (callback with MessageInfo) reads it: every has_part sample is stamped with
    the time of a published pose, and robot_0's cmd_vel answers carry the stamp of a pose
    (state) they answer; the simulation advances only with those answers."""
    from conftest import ROBOT_NODE
    require_binary(SIM_BRIDGE)
    require_binary(ROBOT_NODE)
    d = next_domain_id()
    ros = Ros(d, 'lockstep_test')
    poses, parts, cmds = [], [], []
    # One robot in lockstep steps as fast as it answers (~1 kHz): with the contract's depth
    # 10, rclpy's Python executor falls behind and its reader history drops poses, so a
    # has_part stamp could not be found among the poses seen (flaky under load, both before
    # and after issue 9). The same reliable/volatile QoS with a deep reader history keeps
    # every sample; matching is unchanged (depth is not part of it).
    deep = QoSProfile(reliability=ROBOT_STREAM.reliability, durability=ROBOT_STREAM.durability,
                      history=HistoryPolicy.KEEP_LAST, depth=5000)
    ros.node.create_subscription(PoseStamped, '/robot_0/pose', poses.append, deep)
    ros.node.create_subscription(Bool, '/robot_0/has_part',
                                 lambda m, info: parts.append(info['source_timestamp']),
                                 deep)
    ros.node.create_subscription(Twist, '/robot_0/cmd_vel',
                                 lambda m, info: cmds.append(info['source_timestamp']),
                                 deep)
    env = child_env(d)
    procs = [Proc([SIM_BRIDGE, '--ros-args', '-p', 'setup:=1.2_1', '-p', 'mode:=lockstep'],
                  tmp_path / 'sim_bridge.log', env),
             Proc([ROBOT_NODE, '--ros-args', '-r', '__ns:=/robot_0', '-p', 'lockstep:=true'],
                  tmp_path / 'robot_node.log', env)]
    try:
        # our three readers match the bridge and the robot at different moments: wait for
        # all three, then judge only samples from after the pose reader's first sample
        ros.spin_until(lambda: min(len(cmds), len(poses), len(parts)) >= 50,
                       DISCOVERY_TIMEOUT_S, '50 lockstep poses, has_part and cmd_vel')
        ros.spin_for(0.3)

        def us(ns):
            return (ns + 500) // 1000
        states = {us(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
                  for m in poses}
        assert len(states) >= 50
        first = min(states)
        stamped_parts = [us(t) for t in parts if us(t) >= first]
        assert len(stamped_parts) >= 25, len(stamped_parts)
        assert sum(t in states for t in stamped_parts) >= 0.95 * len(stamped_parts), \
            'has_part source timestamps are not the pose stamps of the same state'
        answered = [us(t) for t in cmds if us(t) >= first]
        assert len(answered) >= 25, len(answered)
        assert sum(t in states for t in answered) >= 0.9 * len(answered), \
            'cmd_vel source timestamps are not the stamps of published states'
        print(f'lockstep: {len(states)} states, {len(parts)} has_part, {len(answered)} cmd_vel, '
              f'{sum(t in states for t in answered)} answering a state; e.g. {answered[:3]} vs {sorted(states)[:3]}')
        # one answer per state, in order
        assert answered == sorted(answered) and len(set(answered)) == len(answered)
    finally:
        codes = [p.terminate() for p in reversed(procs)]
        ros.close()
    assert codes == [0, 0], codes


CELL_TOPIC = re.compile(r'^/tending/cells/c(\d+)_(\d+)$')


def test_cell_topics_are_readable_by_rclpy(tmp_path):
    """Cell topics (docs/adr/0038-cell-topics.md) read by a stranger's rclpy node written from
    the contract: `cell_size:=1.0` on the 2.3 m room gives 3 x 3 cells, each a
    nav_msgs/msg/Path (reliable, transient local, depth 1) whose poses name their entity in
    header.frame_id and carry its flag in position.z. At one step every robot, machine and
    storage is in exactly one cell, the one its position falls in."""
    from nav_msgs.msg import Path

    require_binary(SIM_BRIDGE)
    d = next_domain_id()
    ros = Ros(d, 'cells_test')
    proc = Proc([SIM_BRIDGE, '--ros-args', '-p', 'setup:=6.4_2', '-p', 'seed:=3',
                 '-p', 'cell_size:=1.0', '-p', 'startup_grace_s:=300',
                 '-p', 'wait_for_robots:=false'], tmp_path / 'sim_bridge.log', child_env(d))
    try:
        def cells():
            return {t: ty for t, ty in ros.node.get_topic_names_and_types()
                    if CELL_TOPIC.match(t)}
        ros.spin_until(lambda: len(cells()) == 9, DISCOVERY_TIMEOUT_S, '9 cell topics')
        assert all(ty == ['nav_msgs/msg/Path'] for ty in cells().values()), cells()
        inbox = {t: [] for t in cells()}
        for t, msgs in inbox.items():
            ros.node.create_subscription(Path, t, msgs.append, LATCHED)

        def stamp(m):
            return m.header.stamp.sec * 10**9 + m.header.stamp.nanosec

        def common():
            sets = [{stamp(m) for m in msgs} for msgs in inbox.values()]
            return set.intersection(*sets) if all(sets) else set()
        ros.spin_until(lambda: common(), DISCOVERY_TIMEOUT_S,
                       'one step on every cell topic')
        s = min(common())
        seen = []
        for t, msgs in inbox.items():
            i, j = map(int, CELL_TOPIC.match(t).groups())
            m = next(m for m in msgs if stamp(m) == s)
            assert m.header.frame_id == 'map'
            for p in m.poses:
                name, pos = p.header.frame_id, p.pose.position
                assert stamp(p) == s, (t, name)
                assert pos.z in (0.0, 1.0), (t, name, pos.z)
                if name.startswith('storage_'):
                    assert pos.z == 0.0
                for v, k in ((pos.x, i), (pos.y, j)):
                    assert min(int((v + ROOM_HALF) // 1.0), 2) == max(k, 0), (t, name, v)
                seen.append(name)
        expected = ([f'robot_{i}' for i in range(N_ROBOTS)]
                    + [f'machine_{j}' for j in range(N_MACHINES)]
                    + [f'storage_{k}' for k in range(N_STORAGES)])
        assert sorted(seen) == sorted(expected)
    finally:
        code = proc.terminate()
        ros.close()
        assert code == 0, f'sim_bridge exit code {code}; log:\n{proc.text()[-2000:]}'
