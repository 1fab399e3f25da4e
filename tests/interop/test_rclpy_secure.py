"""An rclpy participant without DDS Security is kept out of a secure fleet (issue 12).

sim_bridge (setup 2.2_2) and robot_1's robot_node run with the enclaves of a keystore that
`tending security create` made, ROS_SECURITY_STRATEGY=Enforce. Real rclpy (Fast DDS; the
PyPI wheels have no security plugins, so it cannot join securely) joins the same domain
without security, subscribes to the fleet's topics and publishes /robot_0/cmd_vel (robot_0
has no node of its own). It must read nothing, and the bridge must never receive its
commands: the bridge records every cmd_vel it receives (`-p record:=DIR`), so the bag shows
robot_1's commands (the secure control) and none for robot_0.
"""

import re
import subprocess

import pytest

from conftest import (
    CLOCK,
    LATCHED,
    RELEASE,
    ROBOT_NODE,
    ROBOT_STREAM,
    SIM_BRIDGE,
    VISUALIZATION,
    Periodic,
    Ros,
    pose_msg,
    require_binary,
)
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Bool

TENDING = RELEASE / 'tending'


def secure(keystore):
    return {'ROS_SECURITY_KEYSTORE': keystore, 'ROS_SECURITY_ENABLE': 'true',
            'ROS_SECURITY_STRATEGY': 'Enforce'}


def bag_counts(bag):
    """topic -> message count, from `tending bag info`."""
    out = subprocess.run([TENDING, 'bag', 'info', bag], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, f'tending bag info {bag}: {out.stderr}'
    counts = {}
    for line in out.stdout.splitlines():
        m = re.match(r'^(/\S+)\s+\S+\s+(\d+)\s', line)
        if m:
            counts[m.group(1)] = int(m.group(2))
    return counts, out.stdout


def test_an_insecure_rclpy_node_reads_nothing_and_moves_nothing(ros, spawn, tmp_path):
    for b in (TENDING, SIM_BRIDGE, ROBOT_NODE):
        require_binary(b)
    ks = tmp_path / 'keystore'
    subprocess.run([TENDING, 'security', 'create', ks, '--fleet', '2'], check=True,
                   capture_output=True, timeout=60)
    bag = tmp_path / 'bridge_bag'

    # The stranger listens to everything a robot or RViz would, and commands robot_0.
    inbox = {}

    def listen(msg_type, topic, qos):
        inbox[topic] = []
        ros.node.create_subscription(msg_type, topic, inbox[topic].append, qos)

    for r in ('robot_0', 'robot_1'):
        listen(PoseStamped, f'/{r}/pose', ROBOT_STREAM)
        listen(Bool, f'/{r}/has_part', ROBOT_STREAM)
    listen(PoseStamped, '/machine_0/pose', LATCHED)
    listen(Clock, '/clock', CLOCK)
    listen(DiagnosticArray, '/tending/metrics', VISUALIZATION)

    def drive():
        m = Twist()
        m.linear.x = 0.5
        return m
    rogue = Periodic(ros, Twist, '/robot_0/cmd_vel', ROBOT_STREAM, drive)

    # Control: rclpy works on this domain (a second, also insecure, rclpy participant's
    # samples arrive), so an empty inbox below means "kept out", not "rclpy broken".
    other = Ros(ros.domain_id, 'open_peer')
    try:
        Periodic(other, PoseStamped, '/robot_9/pose', ROBOT_STREAM,
                 lambda: pose_msg(other.node, 0.1, 0.2))
        listen(PoseStamped, '/robot_9/pose', ROBOT_STREAM)

        # robot_0 is kept (no cmd_vel from a node of its own) for the whole test.
        bridge = spawn([SIM_BRIDGE, '--ros-args', '-p', 'setup:=2.2_2', '-p', 'seed:=0',
                        '-p', 'startup_grace_s:=300', '-p', 'wait_for_robots:=false',
                        '-p', 'metrics_period_s:=0.5',
                        '-p', f'record:={bag}', '--enclave', '/tending/sim_bridge'],
                       name='sim_bridge', **secure(ks))
        robot = spawn([ROBOT_NODE, '--ros-args', '-r', '__ns:=/robot_1',
                       '-p', 'stats_period_s:=0.5', '--enclave', '/tending/robot_1'],
                      name='robot_node', **secure(ks))

        def spin_both(seconds):
            end = seconds
            while end > 0:
                ros.spin_for(0.05)
                other.executor.spin_once(timeout_sec=0.0)
                end -= 0.05

        # The secure pair works: robot_1 acts on the bridge's state (>= 20 commands).
        end_by = 60.0
        rx = re.compile(r'counters robot_1: .* commands=(\d+)')
        while True:
            spin_both(0.5)
            end_by -= 0.5
            for p in (bridge, robot):
                assert p.alive(), f'{p.argv[0]} exited {p.p.returncode}:\n{p.text()[-3000:]}'
            n = [int(x) for x in rx.findall(robot.text())]
            if n and n[-1] >= 20:
                break
            if end_by <= 0:
                pytest.fail(f'secure robot_1 sent {n[-1:] or 0} commands in 60 s; '
                            f'robot_node log:\n{robot.text()[-3000:]}')
        # 10 s more of the stranger commanding robot_0 and listening.
        spin_both(10.0)
        sent = rogue.sent
        assert bridge.terminate() in (0, -15), bridge.text()[-3000:]
        robot.terminate()
    finally:
        other.close()

    control = len(inbox.pop('/robot_9/pose'))
    assert control > 0, 'control: rclpy received nothing from another rclpy participant'
    got = {t: len(v) for t, v in inbox.items() if v}
    assert not got, f'an insecure rclpy node read the secure fleet: {got}'

    counts, info = bag_counts(bag)
    print(info)
    assert sent >= 100, f'the stranger sent only {sent} cmd_vel'
    assert counts.get('/robot_1/cmd_vel', 0) >= 20, \
        f'control: the bridge received too few of robot_1\'s secure commands\n{info}'
    assert counts.get('/robot_0/pose', 0) > 0, f'the bridge published no robot_0 pose\n{info}'
    assert counts.get('/robot_0/cmd_vel', 0) == 0, \
        f'the bridge received the insecure rclpy node\'s cmd_vel for robot_0\n{info}'
