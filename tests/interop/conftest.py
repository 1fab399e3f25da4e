"""Shared helpers of the rclpy interop tests.

Every test gets its own ROS_DOMAIN_ID, leased (tests/domain_lease.py) so that the Rust
tests running at the same time and leftovers of the previous test (DDS endpoints of a
process that just exited, latched samples) do not clash. Every wait is bounded.
"""

import math
import os
import pathlib
import re
import signal
import subprocess
import sys
import time

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
# TENDING_BIN_DIR: where the cargo release binaries are (default target/release)
RELEASE = pathlib.Path(os.environ.get('TENDING_BIN_DIR') or REPO / 'target' / 'release')
ROBOT_NODE = RELEASE / 'robot_node'
SIM_BRIDGE = RELEASE / 'sim_bridge'

# Fast DDS vs RustDDS discovery on a loaded 2-core machine: allow generous bounds.
DISCOVERY_TIMEOUT_S = 20.0

sys.path.insert(0, str(REPO / 'tests'))
from domain_lease import lease  # noqa: E402


def next_domain_id():
    return lease()


@pytest.fixture
def domain_id():
    return next_domain_id()


def require_binary(path):
    if not (path.is_file() and os.access(path, os.X_OK)):
        pytest.skip(f'{path} is not built yet (cargo build --release)')
    return path


# --------------------------------------------------------------------------------- rclpy

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import (  # noqa: E402
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from geometry_msgs.msg import PoseStamped, Twist  # noqa: E402
from std_msgs.msg import Bool  # noqa: E402

# The contract (DESIGN.md).
ROBOT_STREAM = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE,
                          history=HistoryPolicy.KEEP_LAST, depth=10)
LATCHED = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST, depth=1)
CLOCK = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.VOLATILE,
                   history=HistoryPolicy.KEEP_LAST, depth=1)
VISUALIZATION = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE,
                           history=HistoryPolicy.KEEP_LAST, depth=10)
ROOM_HALF = 1.15


def pose_msg(node, x, y):
    m = PoseStamped()
    m.header.frame_id = 'map'
    m.header.stamp = node.get_clock().now().to_msg()
    m.pose.position.x = float(x)
    m.pose.position.y = float(y)
    m.pose.orientation.w = 1.0
    return m


def bool_msg(v):
    m = Bool()
    m.data = bool(v)
    return m


class Ros:
    """One rclpy context on a private domain, one node, a single-threaded executor."""

    def __init__(self, domain_id, name='interop_test'):
        self.domain_id = domain_id
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(f'{name}_{os.getpid()}', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def spin_until(self, pred, timeout, what='condition'):
        """Spin until pred() is truthy; return its value, or fail after `timeout` s."""
        end = time.monotonic() + timeout
        while True:
            v = pred()
            if v:
                return v
            if time.monotonic() >= end:
                pytest.fail(f'timed out after {timeout:.0f} s waiting for {what}\n'
                            f'rclpy graph on domain {self.domain_id}: {self.graph_summary()}')
            self.executor.spin_once(timeout_sec=0.05)

    def graph_summary(self):
        try:
            nodes = self.node.get_node_names_and_namespaces()
            topics = self.node.get_topic_names_and_types()
            return f'nodes {nodes}; {len(topics)} topics: {[t for t, _ in topics][:40]}'
        except Exception as e:  # diagnostics only
            return f'(graph unavailable: {e!r})'

    def close(self):
        try:
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
        finally:
            rclpy.shutdown(context=self.context)


@pytest.fixture
def ros(domain_id):
    r = Ros(domain_id)
    yield r
    r.close()


class Periodic:
    """Publish (topic, msg_fn) at `hz` from an rclpy timer; msg_fn() builds the sample.

    `value` holds what to send; set `active = False` to stop sending."""

    def __init__(self, ros, msg_type, topic, qos, make, hz=20.0):
        self.pub = ros.node.create_publisher(msg_type, topic, qos)
        self.make = make
        self.active = True
        self.sent = 0
        self.timer = ros.node.create_timer(1.0 / hz, self._tick)

    def _tick(self):
        if self.active:
            self.pub.publish(self.make())
            self.sent += 1


class CmdLog:
    """Every Twist received on a cmd_vel topic, with its arrival time."""

    def __init__(self, ros, topic, qos=ROBOT_STREAM):
        self.msgs = []
        self.sub = ros.node.create_subscription(Twist, topic, self._on, qos)

    def _on(self, m):
        v = (m.linear.x, m.linear.y, m.linear.z, m.angular.x, m.angular.y, m.angular.z)
        assert all(math.isfinite(x) for x in v), f'non-finite cmd_vel {v}'
        self.msgs.append((time.monotonic(), m))

    def last(self):
        return self.msgs[-1][1] if self.msgs else None

    def since(self, t):
        return [m for (at, m) in self.msgs if at >= t]


def planar(m):
    return (round(m.linear.x, 6), round(m.linear.y, 6))


# ------------------------------------------------------------------------ child processes

class Proc:
    """A child process whose stderr+stdout go to a log file that tests can wait on."""

    def __init__(self, argv, log_path, env):
        self.argv = [str(a) for a in argv]
        self.log_path = log_path
        self._log = open(log_path, 'wb')
        self.p = subprocess.Popen(self.argv, stdout=self._log, stderr=subprocess.STDOUT,
                                  stdin=subprocess.DEVNULL, env=env)

    def text(self):
        return pathlib.Path(self.log_path).read_text(errors='replace')

    def wait_log(self, ros, pattern, timeout, what=None):
        rx = re.compile(pattern)

        def found():
            if self.p.poll() is not None:
                pytest.fail(f'{self.argv[0]} exited with {self.p.returncode} while waiting '
                            f'for /{pattern}/; log:\n{self.text()[-3000:]}')
            return rx.search(self.text())
        return ros.spin_until(found, timeout, what or f'log line /{pattern}/ of {self.argv[0]}')

    def alive(self):
        return self.p.poll() is None

    def terminate(self, timeout=10.0):
        """SIGTERM, wait; SIGKILL if it hangs. Returns the exit code."""
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            try:
                self.p.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait(timeout=5)
        self._log.close()
        return self.p.returncode


def child_env(domain_id, **extra):
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env.pop('RUST_LOG', None)
    env.update({k: str(v) for k, v in extra.items()})
    return env


@pytest.fixture
def spawn(tmp_path, domain_id):
    """spawn(argv, name=...) -> Proc on this test's domain; terminated at teardown."""
    procs = []

    def _spawn(argv, name='proc', **env_extra):
        p = Proc(argv, tmp_path / f'{name}.log', child_env(domain_id, **env_extra))
        procs.append(p)
        return p
    yield _spawn
    for p in procs:
        code = p.terminate()
        if code not in (0, -signal.SIGTERM):
            print(f'{p.argv[0]} exited with {code}; log tail:\n{p.text()[-2000:]}')
