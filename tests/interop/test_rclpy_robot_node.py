"""robot_node (Rust, ros2-client/RustDDS) against real rclpy (Jazzy, Fast DDS).

rclpy plays sim_bridge: it publishes the robot's pose/has_part and the machine and storage
topics with the contract QoS, and reads robot_node's cmd_vel. Each contract topic is checked
in the direction it is used in production, by an effect that only a delivered sample can
cause (the greedy controller's command changes with each input).
"""

import re
import signal
import time

import pytest

from conftest import (
    DISCOVERY_TIMEOUT_S,
    LATCHED,
    ROBOT_NODE,
    ROBOT_STREAM,
    CmdLog,
    Periodic,
    Proc,
    Ros,
    bool_msg,
    child_env,
    next_domain_id,
    planar,
    pose_msg,
    require_binary,
)
from geometry_msgs.msg import PoseStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool

K = 0.5  # robot_node's default k_speed
RIGHT, LEFT, UP, DOWN, STAY = (K, 0.0), (-K, 0.0), (0.0, K), (0.0, -K), (0.0, 0.0)
NODE_ARGS = ['--ros-args', '-r', '__ns:=/robot_0', '-p', 'control_rate_hz:=20',
             '-p', 'stats_period_s:=0.5', '-p', 'discovery_period_s:=0.2']


class Scene:
    """What rclpy publishes, as sim_bridge would: robot streams at 20 Hz, latched
    machine/storage topics republished at 5 Hz (robot_node's static staleness default is
    1 s). Change the attributes to change what is published."""

    def __init__(self, ros, robot='robot_0'):
        self.ros = ros
        self.own = [-0.5, -0.5]
        self.has_part = False
        self.pubs = {}
        n = ros.node
        self.pubs['own_pose'] = Periodic(ros, PoseStamped, f'/{robot}/pose', ROBOT_STREAM,
                                         lambda: pose_msg(n, *self.own))
        self.pubs['own_part'] = Periodic(ros, Bool, f'/{robot}/has_part', ROBOT_STREAM,
                                         lambda: bool_msg(self.has_part))

    def machine(self, j, xy, ready):
        st = {'xy': list(xy), 'ready': ready}
        n = self.ros.node
        self.pubs[f'm{j}_pose'] = Periodic(self.ros, PoseStamped, f'/machine_{j}/pose', LATCHED,
                                           lambda: pose_msg(n, *st['xy']), hz=5)
        self.pubs[f'm{j}_ready'] = Periodic(self.ros, Bool, f'/machine_{j}/part_ready', LATCHED,
                                            lambda: bool_msg(st['ready']), hz=5)
        return st

    def storage(self, k, xy):
        st = {'xy': list(xy)}
        n = self.ros.node
        self.pubs[f's{k}_pose'] = Periodic(self.ros, PoseStamped, f'/storage_{k}/pose', LATCHED,
                                           lambda: pose_msg(n, *st['xy']), hz=5)
        return st

    def peer(self, name, xy, has_part=False):
        st = {'xy': list(xy), 'has_part': has_part}
        n = self.ros.node
        self.pubs[f'{name}_pose'] = Periodic(self.ros, PoseStamped, f'/{name}/pose', ROBOT_STREAM,
                                             lambda: pose_msg(n, *st['xy']))
        self.pubs[f'{name}_part'] = Periodic(self.ros, Bool, f'/{name}/has_part', ROBOT_STREAM,
                                             lambda: bool_msg(st['has_part']))
        return st


def wait_cmd(ros, cmd, want, timeout=DISCOVERY_TIMEOUT_S, what=None):
    """Spin until the latest cmd_vel is `want` (vx, vy); the command must then hold."""
    ros.spin_until(lambda: cmd.last() is not None and planar(cmd.last()) == want, timeout,
                   what or f'cmd_vel {want} (last: {cmd.last() and planar(cmd.last())})')
    t = time.monotonic()
    ros.spin_for(0.3)
    later = [planar(m) for m in cmd.since(t)]
    assert later, 'cmd_vel stopped arriving'
    assert all(v == want for v in later), f'cmd_vel not steady at {want}: {later}'


@pytest.fixture
def node(spawn):
    require_binary(ROBOT_NODE)

    def start(*extra):
        return spawn([ROBOT_NODE, *NODE_ARGS, *extra], name='robot_node')
    return start


# ------------------------------------------------------------------ delivery, per topic

def test_cmd_vel_reaches_rclpy_and_points_toward_ready_machine(ros, node):
    """/robot_0/cmd_vel (Rust -> rclpy, reliable) carries the greedy command toward the
    ready machine; inputs: own pose + has_part, machine pose + part_ready, storage pose.
    Then: own pose stops -> zero; SIGTERM -> a final zero reaches rclpy and exit code 0."""
    cmd = CmdLog(ros, '/robot_0/cmd_vel')
    s = Scene(ros)
    s.machine(0, (0.5, -0.5), True)
    s.storage(0, (-0.5, 0.8))
    p = node()
    wait_cmd(ros, cmd, RIGHT)
    # every command so far is a valid action velocity
    assert {planar(m) for (_, m) in cmd.msgs} <= {RIGHT, STAY}

    # own pose stops: stale after 1 s -> zero velocity
    s.pubs['own_pose'].active = False
    t = time.monotonic()
    wait_cmd(ros, cmd, STAY, timeout=5.0, what='zero cmd_vel after own pose went stale')
    assert time.monotonic() - t < 3.5

    # back, then SIGTERM: the last command delivered is zero, exit 0
    s.pubs['own_pose'].active = True
    wait_cmd(ros, cmd, RIGHT, timeout=5.0)
    n_before = len(cmd.msgs)
    p.p.send_signal(signal.SIGTERM)
    ros.spin_until(lambda: p.p.poll() is not None, 10.0, 'robot_node exit after SIGTERM')
    ros.spin_for(0.5)
    assert p.p.returncode == 0, p.text()[-2000:]
    assert len(cmd.msgs) > n_before
    assert planar(cmd.last()) == STAY, 'the last cmd_vel after SIGTERM is not zero'


def test_own_pose_values_drive_the_command(ros, node):
    """/robot_0/pose (rclpy -> Rust, reliable volatile depth 10): moving the published pose
    flips the command, so pose samples (not just the first) are delivered."""
    cmd = CmdLog(ros, '/robot_0/cmd_vel')
    s = Scene(ros)
    s.machine(0, (0.5, -0.5), True)
    s.storage(0, (-0.5, 0.8))
    node()
    wait_cmd(ros, cmd, RIGHT)
    s.own = [1.0, -0.5]      # east of the machine
    wait_cmd(ros, cmd, LEFT, timeout=5.0)
    s.own = [0.5, -0.95]     # south of it
    wait_cmd(ros, cmd, UP, timeout=5.0)
    s.own = [-0.5, -0.45]    # back west, slightly north: the larger gap (x) wins
    wait_cmd(ros, cmd, RIGHT, timeout=5.0)


def test_has_part_and_storage_pose(ros, node):
    """/robot_0/has_part (rclpy -> Rust): with a part the robot heads to the storage
    (/storage_0/pose, transient local), without one back to the machine."""
    cmd = CmdLog(ros, '/robot_0/cmd_vel')
    s = Scene(ros)
    s.machine(0, (0.5, -0.5), True)
    storage = s.storage(0, (-0.5, 0.8))
    node()
    wait_cmd(ros, cmd, RIGHT)
    s.has_part = True
    wait_cmd(ros, cmd, UP, timeout=5.0)
    storage['xy'] = [-1.0, -0.6]   # storage moves west: pose updates are delivered
    wait_cmd(ros, cmd, LEFT, timeout=5.0)
    s.has_part = False
    wait_cmd(ros, cmd, RIGHT, timeout=5.0)


def test_part_ready_selects_the_machine(ros, node):
    """/machine_<j>/pose and /machine_<j>/part_ready (rclpy -> Rust, transient local depth 1):
    a second machine is discovered and the ready one is chosen over the nearer one; with
    no machine ready the greedy controller stays."""
    cmd = CmdLog(ros, '/robot_0/cmd_vel')
    s = Scene(ros)
    m0 = s.machine(0, (0.0, -0.5), False)   # nearer (0.5 m east), not ready
    m1 = s.machine(1, (-0.5, 0.6), True)    # farther (1.1 m north), ready
    s.storage(0, (1.0, 1.0))
    p = node()
    wait_cmd(ros, cmd, UP)
    m1['ready'] = False
    m0['ready'] = True
    wait_cmd(ros, cmd, RIGHT, timeout=5.0)
    # neither ready: stay
    m0['ready'] = False
    wait_cmd(ros, cmd, STAY, timeout=5.0)
    assert re.search(r'discovered /machine_1/part_ready', p.text())


def test_latched_topics_reach_a_late_joining_robot(ros, node):
    """Transient-local durability agreement: machine pose, part_ready and storage pose are
    published ONCE by rclpy before robot_node starts; robot_node (static staleness off) must
    still get them from the writers' history. A volatile Rust subscription would get
    nothing and the robot would stay."""
    cmd = CmdLog(ros, '/robot_0/cmd_vel')
    n = ros.node
    once = [
        (ros.node.create_publisher(PoseStamped, '/machine_0/pose', LATCHED), pose_msg(n, 0.5, -0.5)),
        (ros.node.create_publisher(Bool, '/machine_0/part_ready', LATCHED), bool_msg(True)),
        (ros.node.create_publisher(PoseStamped, '/storage_0/pose', LATCHED), pose_msg(n, -0.5, 0.8)),
    ]
    for pub, msg in once:
        pub.publish(msg)
    ros.spin_for(0.5)
    s = Scene(ros)   # own pose/has_part keep streaming
    node('-p', 'static_stale_timeout_s:=0')
    wait_cmd(ros, cmd, RIGHT, what='command toward a machine known only from latched samples')
    # with part: to the storage, also known only from its latched sample
    s.has_part = True
    wait_cmd(ros, cmd, UP, timeout=5.0)


def test_peer_pose_published_by_rclpy_is_discovered(ros, node):
    """/robot_9/pose + /robot_9/has_part published by rclpy: robot_node finds the peer by
    topic discovery alone, receives its samples (peers=1 in its counters), puts it into its
    observation (the 'controlling' rosout line, read by rclpy on /rosout, counts it), and
    its greedy controller yields the machine to the nearer part-less peer."""
    from rcl_interfaces.msg import Log
    logs = []
    ros.node.create_subscription(
        Log, '/rosout', logs.append,
        QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT,
                   durability=DurabilityPolicy.VOLATILE))
    cmd = CmdLog(ros, '/robot_0/cmd_vel')
    s = Scene(ros)
    s.pubs['own_pose'].active = False     # hold own pose back until everything is known
    s.machine(0, (0.5, -0.5), True)
    s.storage(0, (-0.5, 0.8))
    peer = s.peer('robot_9', (0.9, 0.9), True)
    p = node()
    for t in ('/robot_9/pose', '/robot_9/has_part', '/machine_0/pose', '/machine_0/part_ready',
              '/storage_0/pose'):
        p.wait_log(ros, rf'discovered {re.escape(t)}\b', DISCOVERY_TIMEOUT_S)
    p.wait_log(ros, r'known machines=1 storages=1 peers=1', 5.0,
               'robot_node counters with one peer')
    # a reader's first samples follow its discovery line by a few hundred ms (reliable
    # matching); give every stream time to flow before the first observation is built
    ros.spin_for(2.0)
    s.pubs['own_pose'].active = True
    wait_cmd(ros, cmd, RIGHT)    # the peer does not change the greedy command

    def controlling():
        for m in logs:
            if 'controlling: observation counts' in m.msg:
                return m
    m = ros.spin_until(controlling, 5.0, "robot_node's 'controlling' log on /rosout")
    assert 'peers: 1' in m.msg and 'machines: 1' in m.msg and 'storages: 1' in m.msg, m.msg
    assert m.name.endswith('robot_node'), m.name

    # the greedy claim rule: a part-less peer nearer to the only ready machine takes it
    peer['xy'] = [0.5, -0.1]          # 0.4 m from the machine (robot_0: 1.0 m)
    peer['has_part'] = False
    wait_cmd(ros, cmd, STAY, timeout=5.0, what='robot_0 yielding the machine to robot_9')
    peer['has_part'] = True           # a peer carrying a part claims nothing
    wait_cmd(ros, cmd, RIGHT, timeout=5.0)
    peer['has_part'] = False
    peer['xy'] = [0.5, 0.9]           # part-less again but farther than robot_0 (1.4 m)
    wait_cmd(ros, cmd, RIGHT, timeout=2.0)
    # the Rust node ignores its own cmd_vel and never takes a peer's cmd_vel
    assert 'discovered /robot_0/cmd_vel' not in p.text()


def test_clock_from_rclpy_drives_sim_time_ticks(ros, node):
    """/clock (rosgraph_msgs/Clock, reliable keep-last 1) from rclpy -> Rust: with
    use_sim_time robot_node acts once per 1/control_rate_hz of sim time, so cmd_vel follows
    the published clock (here 4x faster than wall time) and stops when it stops."""
    from rosgraph_msgs.msg import Clock
    from conftest import CLOCK
    cmd = CmdLog(ros, '/robot_0/cmd_vel')
    s = Scene(ros)
    s.machine(0, (0.5, -0.5), True)
    s.storage(0, (-0.5, 0.8))
    sim = {'t': 1.0, 'run': True}

    def clock():
        if sim['run']:
            sim['t'] += 0.1          # one control period of sim time per sample
        m = Clock()
        m.clock.sec = int(sim['t'])
        m.clock.nanosec = int(round((sim['t'] - int(sim['t'])) * 1e9))
        return m
    clk = Periodic(ros, Clock, '/clock', CLOCK, clock, hz=40)
    node('-p', 'use_sim_time:=true', '-p', 'control_rate_hz:=10')
    wait_cmd(ros, cmd, RIGHT)
    n0, c0 = len(cmd.msgs), clk.sent
    ros.spin_for(2.0)
    ticks, steps = len(cmd.msgs) - n0, clk.sent - c0
    # 10 Hz of sim time at 4x: ~40 commands per wall second, far above the wall-clock 10 Hz
    assert 0.6 * steps <= ticks <= steps + 2, f'{ticks} commands for {steps} clock steps'
    sim['run'] = False               # the clock stands still (still published): no ticks
    ros.spin_for(0.5)
    n1 = len(cmd.msgs)
    ros.spin_for(1.0)
    assert len(cmd.msgs) - n1 <= 1, f'{len(cmd.msgs) - n1} commands while sim time stood still'


# ------------------------------------------------------- graph: names, types, QoS (rclpy view)

@pytest.fixture(scope='module')
def live(tmp_path_factory):
    """One robot_node, fed a full scene including a peer, that the graph tests inspect."""
    require_binary(ROBOT_NODE)
    d = next_domain_id()
    ros = Ros(d, 'graph_test')
    cmd = CmdLog(ros, '/robot_0/cmd_vel')
    s = Scene(ros)
    s.machine(0, (0.5, -0.5), True)
    s.storage(0, (-0.5, 0.8))
    s.peer('robot_9', (0.9, 0.9))
    log = tmp_path_factory.mktemp('live') / 'robot_node.log'
    p = Proc([ROBOT_NODE, *NODE_ARGS], log, child_env(d))
    try:
        wait_cmd(ros, cmd, RIGHT)
        p.wait_log(ros, r'discovered /robot_9/has_part', DISCOVERY_TIMEOUT_S)
        # node names arrive a few seconds after the endpoints (ros_discovery_info)
        ros.spin_until(lambda: ('robot_node', '/robot_0') in
                       ros.node.get_node_names_and_namespaces(), DISCOVERY_TIMEOUT_S,
                       'node /robot_0/robot_node in the rclpy graph')
        yield ros, p
    finally:
        code = p.terminate()
        ros.close()
        assert code == 0, f'robot_node exit code {code}'


# What robot_node publishes (ROS name -> type). /rosout is ros2-client's logger.
RUST_PUBLISHES = {
    '/robot_0/cmd_vel': 'geometry_msgs/msg/Twist',
    '/rosout': 'rcl_interfaces/msg/Log',
    '/parameter_events': 'rcl_interfaces/msg/ParameterEvent',
}
# What robot_node subscribes to here (own inputs + discovered entities), with the contract QoS.
V, TL = DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL
RUST_SUBSCRIBES = {
    '/robot_0/pose': ('geometry_msgs/msg/PoseStamped', V),
    '/robot_0/has_part': ('std_msgs/msg/Bool', V),
    '/machine_0/pose': ('geometry_msgs/msg/PoseStamped', TL),
    '/machine_0/part_ready': ('std_msgs/msg/Bool', TL),
    '/storage_0/pose': ('geometry_msgs/msg/PoseStamped', TL),
    '/robot_9/pose': ('geometry_msgs/msg/PoseStamped', V),
    '/robot_9/has_part': ('std_msgs/msg/Bool', V),
}


def _by_node(ros, fn):
    return dict(ros.spin_until(lambda: fn('robot_node', '/robot_0') or None, 10.0,
                               f'{fn.__name__} of /robot_0/robot_node'))


def test_rclpy_sees_every_rust_publication_with_its_type(live):
    """Every topic robot_node writes, found from rclpy's graph (all writers in this domain
    that are not rclpy's), has the contract type, and includes /robot_0/cmd_vel.

    cmd_vel goes through a plain RustDDS writer (msgs::dds::StampedWriter, for source
    timestamps) that is not registered in ros_discovery_info: rclpy sees the topic and its
    writer but cannot attribute it to the node (`ros2 node info` omits it; documented
    trade-off in msgs/src/dds.rs). The node-attributed list is checked to be a subset."""
    ros, _ = live
    mine = ros.node.get_name()
    rust = {}
    for topic, types in ros.node.get_topic_names_and_types():
        for ep in ros.node.get_publishers_info_by_topic(topic):
            if ep.node_name != mine:
                rust.setdefault(topic, set()).add(ep.topic_type)
                assert ep.topic_type in types
    assert '/robot_0/cmd_vel' in rust, rust
    for topic, types in rust.items():
        assert topic in RUST_PUBLISHES, f'unexpected publication {topic} {types}'
        assert types == {RUST_PUBLISHES[topic]}, f'{topic}: {types}'
    by_node = _by_node(ros, ros.node.get_publisher_names_and_types_by_node)
    for topic, types in by_node.items():
        assert topic in rust and set(types) == rust[topic], f'{topic}: {types}'


def test_rclpy_sees_every_rust_subscription_with_its_type(live):
    ros, _ = live
    subs = ros.spin_until(
        lambda: (lambda d: d if set(RUST_SUBSCRIBES) <= set(d) else None)(
            dict(ros.node.get_subscriber_names_and_types_by_node('robot_node', '/robot_0'))),
        10.0, 'all subscriptions of /robot_0/robot_node')
    for topic, (typ, _) in RUST_SUBSCRIBES.items():
        assert subs[topic] == [typ], f'{topic}: {subs[topic]}'
    # no subscription outside the contract (/clock only with use_sim_time)
    for topic in subs:
        assert topic in RUST_SUBSCRIBES, f'unexpected subscription {topic}'


def _rust_endpoints(ros, infos):
    # our rclpy node is the only other participant in this domain
    return [i for i in infos if i.node_name != ros.node.get_name()]


def test_cmd_vel_publisher_qos(live):
    """The Rust cmd_vel writer is reliable + volatile (a best-effort one would reach no
    reliable subscriber, silently)."""
    ros, _ = live
    eps = _rust_endpoints(ros, ros.node.get_publishers_info_by_topic('/robot_0/cmd_vel'))
    assert len(eps) == 1, eps
    q = eps[0].qos_profile
    assert eps[0].topic_type == 'geometry_msgs/msg/Twist'
    assert q.reliability == ReliabilityPolicy.RELIABLE, q
    assert q.durability == DurabilityPolicy.VOLATILE, q


@pytest.mark.parametrize('topic', sorted(RUST_SUBSCRIBES))
def test_rust_subscription_qos(live, topic):
    """Each Rust reader: reliable, and transient local exactly on latched topics (a
    transient-local reader on a volatile writer would match nothing)."""
    ros, _ = live
    typ, durability = RUST_SUBSCRIBES[topic]
    eps = _rust_endpoints(ros, ros.node.get_subscriptions_info_by_topic(topic))
    assert len(eps) == 1, f'{topic}: {eps}'
    q = eps[0].qos_profile
    assert eps[0].topic_type == typ
    assert q.reliability == ReliabilityPolicy.RELIABLE, f'{topic}: {q}'
    assert q.durability == durability, f'{topic}: {q}'


def test_no_reader_outside_the_contract(live):
    """Graph-wide (attributed to the node or not): robot_node reads only contract topics,
    each with its contract type. /clock (rosgraph_msgs/Clock) is in the contract: the
    ros2-client spinner reads it for use_sim_time."""
    ros, _ = live
    mine = ros.node.get_name()
    allowed = {t: typ for t, (typ, _) in RUST_SUBSCRIBES.items()}
    allowed['/clock'] = 'rosgraph_msgs/msg/Clock'
    extra = {}
    for topic, _ in ros.node.get_topic_names_and_types():
        for ep in ros.node.get_subscriptions_info_by_topic(topic):
            if ep.node_name != mine and topic != '/parameter_events' \
                    and allowed.get(topic) != ep.topic_type:
                extra.setdefault(topic, set()).add(ep.topic_type)
    assert not extra, extra
