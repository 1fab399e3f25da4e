"""launch-scripts/: the ament install layout (what `ros2 run` / `ros2 launch` rely on) and
the fleet launch file.

`launch` / `launch_ros` are not on PyPI (only in ROS distributions), so the launch file is
executed against minimal stand-ins of the four names it uses (same signatures as the real
API), and the command line that launch_ros builds for such a Node (launch_ros
actions/node.py: `--ros-args -r __node:=N -r __ns:=/NS --params-file F`, F keyed by the
fully qualified node name) is reproduced and run against the real robot_node.
"""

import importlib.util
import os
import re
import subprocess
import sys
import types
import xml.etree.ElementTree as ET

import pytest
import rclpy
import yaml

from conftest import (
    DISCOVERY_TIMEOUT_S,
    LATCHED,
    REPO,
    RELEASE,
    ROBOT_NODE,
    ROBOT_STREAM,
    SIM_BRIDGE,
    next_domain_id,
    CmdLog,
    Periodic,
    bool_msg,
    planar,
    pose_msg,
    require_binary,
)
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import Bool

SCRIPTS = REPO / 'launch-scripts'
INSTALL = SCRIPTS / 'install.sh'


def run_install(prefix, *opts, bin_dir=RELEASE):
    env = dict(os.environ, TENDING_BIN_DIR=str(bin_dir))
    return subprocess.run(['bash', str(INSTALL), *opts, str(prefix)], env=env,
                          capture_output=True, text=True, timeout=60)


@pytest.fixture
def prefix(tmp_path):
    require_binary(ROBOT_NODE)
    opts = [] if SIM_BRIDGE.exists() else ['--allow-missing']
    r = run_install(tmp_path / 'install', *opts)
    assert r.returncode == 0, r.stderr
    return tmp_path / 'install'


def test_install_lays_out_an_ament_prefix(prefix):
    assert (prefix / 'share/ament_index/resource_index/packages/tending').is_file()
    manifest = ET.parse(prefix / 'share/tending/package.xml').getroot()
    assert manifest.tag == 'package' and manifest.get('format') == '3'
    assert manifest.findtext('name') == 'tending'
    launch = prefix / 'share/tending/launch/fleet.launch.py'
    assert launch.read_bytes() == (SCRIPTS / 'fleet.launch.py').read_bytes()
    exe = prefix / 'lib/tending/robot_node'
    assert exe.is_file() and os.access(exe, os.X_OK)
    assert exe.read_bytes() == ROBOT_NODE.read_bytes()
    if SIM_BRIDGE.exists():
        assert os.access(prefix / 'lib/tending/sim_bridge', os.X_OK)


def test_install_is_idempotent_and_can_symlink(prefix):
    opts = [] if SIM_BRIDGE.exists() else ['--allow-missing']
    r = run_install(prefix, '--symlink', *opts)
    assert r.returncode == 0, r.stderr
    link = prefix / 'lib/tending/robot_node'
    assert link.is_symlink() and os.path.samefile(link, ROBOT_NODE)


def test_install_refuses_a_missing_binary(tmp_path):
    empty = tmp_path / 'nothing_built'
    empty.mkdir()
    r = run_install(tmp_path / 'install', bin_dir=empty)
    assert r.returncode == 1
    assert 'robot_node' in r.stderr and 'not built' in r.stderr
    r = run_install(tmp_path / 'install', '--allow-missing', bin_dir=empty)
    assert r.returncode == 1 and 'no binary installed' in r.stderr
    r = subprocess.run(['bash', str(INSTALL)], capture_output=True, text=True, timeout=10)
    assert r.returncode == 2 and 'usage' in r.stderr


def ros2_run_resolve(package, executable):
    """What `ros2 run PACKAGE EXECUTABLE` does (ros2pkg.api.get_executable_paths): the
    package prefix from the ament index, then an executable file in PREFIX/lib/PACKAGE."""
    from ament_index_python.packages import get_package_prefix
    base = os.path.join(get_package_prefix(package), 'lib', package)
    found = []
    for dirpath, _, files in os.walk(base):
        for f in files:
            p = os.path.join(dirpath, f)
            if f == executable and os.access(p, os.X_OK):
                found.append(p)
    return found


def test_ament_index_resolves_the_package(prefix, monkeypatch):
    from ament_index_python.packages import (
        PackageNotFoundError,
        get_package_prefix,
        get_package_share_directory,
        get_packages_with_prefixes,
    )
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    assert get_package_prefix('tending') == str(prefix)
    assert get_package_share_directory('tending') == str(prefix / 'share/tending')
    assert get_packages_with_prefixes() == {'tending': str(prefix)}
    assert ros2_run_resolve('tending', 'robot_node') == [str(prefix / 'lib/tending/robot_node')]
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix.parent / 'elsewhere'))
    with pytest.raises(PackageNotFoundError):
        get_package_prefix('tending')


def _feed_robot(ros, robot):
    n = ros.node
    return [
        Periodic(ros, PoseStamped, f'/{robot}/pose', ROBOT_STREAM, lambda: pose_msg(n, -0.5, -0.5)),
        Periodic(ros, Bool, f'/{robot}/has_part', ROBOT_STREAM, lambda: bool_msg(False)),
        Periodic(ros, PoseStamped, '/machine_0/pose', LATCHED, lambda: pose_msg(n, 0.5, -0.5), hz=5),
        Periodic(ros, Bool, '/machine_0/part_ready', LATCHED, lambda: bool_msg(True), hz=5),
    ]


def test_ros2_run_style_start_of_the_installed_node(prefix, monkeypatch, ros, spawn):
    """The path `ros2 run tending robot_node` would exec, started with
    `--ros-args -r __ns:=/robot_3 -p control_rate_hz:=10`, drives /robot_3 at ~10 Hz."""
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    [exe] = ros2_run_resolve('tending', 'robot_node')
    cmd = CmdLog(ros, '/robot_3/cmd_vel')
    feeds = _feed_robot(ros, 'robot_3')
    p = spawn([exe, '--ros-args', '-r', '__ns:=/robot_3', '-p', 'control_rate_hz:=10'],
              name='robot_3')
    ros.spin_until(lambda: cmd.last() is not None and planar(cmd.last()) == (0.5, 0.0),
                   DISCOVERY_TIMEOUT_S, 'a command toward the machine on /robot_3/cmd_vel')
    n0 = len(cmd.msgs)
    ros.spin_for(2.0)
    rate = (len(cmd.msgs) - n0) / 2.0
    assert 6.0 <= rate <= 14.0, f'cmd_vel at {rate} Hz, want ~10'
    assert 'robot_node /robot_3/robot_node up' in p.text()
    assert feeds[0].sent > 0


# ------------------------------------------------------------------------- launch file

class _Stub:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration:
    def __init__(self, name, default=None):
        self.name, self.default = name, default

    def perform(self, context):
        return context.launch_configurations[self.name]


def load_launch_file(path, monkeypatch):
    launch = types.ModuleType('launch')
    launch.LaunchDescription = type('LaunchDescription', (_Stub,), {})
    actions = types.ModuleType('launch.actions')
    actions.DeclareLaunchArgument = type('DeclareLaunchArgument', (_Stub,), {})
    actions.OpaqueFunction = type('OpaqueFunction', (_Stub,), {})
    subs = types.ModuleType('launch.substitutions')
    subs.LaunchConfiguration = _LaunchConfiguration
    launch_ros = types.ModuleType('launch_ros')
    ros_actions = types.ModuleType('launch_ros.actions')
    ros_actions.Node = type('Node', (_Stub,), {})
    launch.actions, launch.substitutions, launch_ros.actions = actions, subs, ros_actions
    for name, mod in [('launch', launch), ('launch.actions', actions),
                      ('launch.substitutions', subs), ('launch_ros', launch_ros),
                      ('launch_ros.actions', ros_actions)]:
        monkeypatch.setitem(sys.modules, name, mod)
    spec = importlib.util.spec_from_file_location('fleet_launch', path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def launch(path, monkeypatch, **overrides):
    """generate_launch_description() then the OpaqueFunction, as `ros2 launch` would with
    `name:=value` overrides; returns the Node actions' keyword arguments."""
    mod = load_launch_file(path, monkeypatch)
    ld = mod.generate_launch_description()
    entities = ld.args[0]
    declared = {e.args[0]: e.kwargs['default_value'] for e in entities
                if type(e).__name__ == 'DeclareLaunchArgument'}
    unknown = set(overrides) - set(declared)
    assert not unknown, f'not launch arguments: {unknown}'
    [opaque] = [e for e in entities if type(e).__name__ == 'OpaqueFunction']
    ctx = types.SimpleNamespace(launch_configurations={**declared, **overrides})
    return [a.kwargs for a in opaque.kwargs['function'](ctx)]


@pytest.fixture(params=['repo', 'installed'])
def launch_file(request, tmp_path):
    if request.param == 'repo':
        return SCRIPTS / 'fleet.launch.py'
    require_binary(ROBOT_NODE)
    r = run_install(tmp_path / 'install', '--allow-missing')
    assert r.returncode == 0, r.stderr
    return tmp_path / 'install/share/tending/launch/fleet.launch.py'


def test_launch_defaults_bridge_and_one_node_per_robot_of_the_setup(launch_file, monkeypatch):
    nodes = launch(launch_file, monkeypatch)
    bridge, robots = nodes[0], nodes[1:]
    assert bridge['package'] == 'tending' and bridge['executable'] == 'sim_bridge'
    assert bridge['parameters'] == [{'setup': '6.4_2', 'seed': 0}]
    assert len(robots) == 6
    for i, r in enumerate(robots):
        assert (r['package'], r['executable'], r['name']) == ('tending', 'robot_node', 'robot_node')
        assert r['namespace'] == f'robot_{i}'
        assert r['parameters'] == [{'use_sim_time': True}]


def test_launch_arguments(launch_file, monkeypatch):
    nodes = launch(launch_file, monkeypatch, setup='10.6_4', seed='7', robots='3',
                   policy='/ckpt/p.safetensors', use_sim_time='false')
    assert nodes[0]['parameters'] == [{'setup': '10.6_4', 'seed': 7}]
    assert [n['namespace'] for n in nodes[1:]] == ['robot_0', 'robot_1', 'robot_2']
    assert nodes[1]['parameters'] == [{'use_sim_time': False, 'policy': '/ckpt/p.safetensors'}]
    nodes = launch(launch_file, monkeypatch, setup='12.8_4', bridge='false', controller='greedy')
    assert [n['executable'] for n in nodes] == ['robot_node'] * 12
    assert nodes[0]['parameters'] == [{'use_sim_time': True, 'controller': 'greedy'}]


@pytest.mark.parametrize('bad', [{'setup': 'six'}, {'robots': '0'}, {'seed': 'x'},
                                 {'use_sim_time': 'maybe'}, {'controller': 'magic'}])
def test_launch_rejects_bad_arguments_naming_them(monkeypatch, bad):
    with pytest.raises(ValueError, match=list(bad)[0]):
        launch(SCRIPTS / 'fleet.launch.py', monkeypatch, **bad)


def test_robot_node_accepts_the_command_line_launch_ros_builds(monkeypatch, tmp_path, ros,
                                                                spawn):
    """launch_ros turns robot i of the launch file into
    `robot_node --ros-args -r __node:=robot_node -r __ns:=/robot_i --params-file F` with
    F = {'/robot_i/robot_node': {'ros__parameters': {...}}} (yaml.dump); run exactly that."""
    require_binary(ROBOT_NODE)
    nodes = launch(SCRIPTS / 'fleet.launch.py', monkeypatch, robots='3', bridge='false',
                   use_sim_time='false', controller='greedy')
    r = nodes[2]
    ns = '/' + r['namespace']
    fq = f"{ns}/{r['name']}"
    params = {}
    for d in r['parameters']:
        params.update(d)
    pfile = tmp_path / 'launch_params_robot_2'
    pfile.write_text(yaml.dump({fq: {'ros__parameters': params}}, default_flow_style=False))
    cmd = CmdLog(ros, '/robot_2/cmd_vel')
    _feed_robot(ros, 'robot_2')
    p = spawn([ROBOT_NODE, '--ros-args', '-r', f"__node:={r['name']}", '-r', f'__ns:={ns}',
               '--params-file', str(pfile)], name='robot_2')
    ros.spin_until(lambda: cmd.last() is not None and planar(cmd.last()) == (0.5, 0.0),
                   DISCOVERY_TIMEOUT_S, 'a command on /robot_2/cmd_vel')
    assert 'robot_node /robot_2/robot_node up' in p.text()
    assert 'wall clock' in p.text() and 'controller greedy' in p.text()


def test_sim_bridge_accepts_the_command_line_launch_ros_builds(monkeypatch, tmp_path, ros,
                                                                spawn):
    """The launch file's bridge node as launch_ros runs it:
    `sim_bridge --ros-args -r __node:=sim_bridge --params-file F`, F keyed `/sim_bridge`
    (launch_ros yaml-dumps str values, so `10.6_4` stays a string); the setup and seed from
    the file take effect (10 robots on the graph)."""
    require_binary(SIM_BRIDGE)
    nodes = launch(SCRIPTS / 'fleet.launch.py', monkeypatch, setup='10.6_4', seed='5')
    b = nodes[0]
    assert b['executable'] == 'sim_bridge' and 'namespace' not in b
    params = {}
    for d in b['parameters']:
        params.update(d)
    pfile = tmp_path / 'launch_params_bridge'
    pfile.write_text(yaml.dump({f"/{b['name']}": {'ros__parameters': params}},
                               default_flow_style=False))
    p = spawn([SIM_BRIDGE, '--ros-args', '-r', f"__node:={b['name']}", '--params-file',
               str(pfile)], name='sim_bridge')
    ros.spin_until(lambda: any(t == '/robot_9/pose' for t, _ in
                               ros.node.get_topic_names_and_types()),
                   DISCOVERY_TIMEOUT_S, '/robot_9/pose of a 10-robot setup')
    assert re.search(r'setup 10\.6_4, seed 5\b', p.text()), p.text()[-1500:]
    assert ('sim_bridge', '/') in ros.spin_until(
        lambda: (lambda n: n if ('sim_bridge', '/') in n else None)(
            ros.node.get_node_names_and_namespaces()), 10.0, 'node /sim_bridge')


def test_launch_passes_a_params_file_first(monkeypatch, tmp_path):
    """params_file:= goes to every node before the launch arguments (which override it)."""
    f = tmp_path / 'fleet.yaml'
    f.write_text('/**/robot_node:\n  ros__parameters:\n    k_speed: 0.4\n')
    nodes = launch(SCRIPTS / 'fleet.launch.py', monkeypatch, robots='2', params_file=str(f))
    assert nodes[0]['parameters'] == [str(f), {'setup': '6.4_2', 'seed': 0}]
    assert nodes[1]['parameters'] == [str(f), {'use_sim_time': True}]
    with pytest.raises(ValueError, match='params_file'):
        launch(SCRIPTS / 'fleet.launch.py', monkeypatch, params_file=str(tmp_path / 'none'))


TENDING = RELEASE / 'tending'


def test_ros2_reads_the_parameters_file_tending_fleet_writes(tmp_path, ros):
    """`tending fleet` writes fleet.yaml and passes it to every child; ROS 2's own parser
    (rcl, through rclpy node overrides, wildcards included) reads the same values with the
    same types: a setup name stays a string, sizes are doubles, counts integers."""
    require_binary(TENDING)
    logs = tmp_path / 'logs'
    r = subprocess.run([TENDING, 'fleet', '--setup', '6.4_2', '--mode', 'lockstep',
                        '--duration', '0.5', '--domain', str(next_domain_id()),
                        '--domain-check', '0', '--no-stdin', '--log-dir', str(logs),
                        '--policy', 'matching-orca'],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert 'controller matching-orca' in r.stderr
    f = logs / 'fleet.yaml'
    from rclpy.parameter import Parameter
    got = {}
    for ns, name in [('/', 'sim_bridge'), ('/robot_3', 'robot_node')]:
        node = rclpy.create_node(name, namespace=ns, context=ros.context,
                                 cli_args=['--ros-args', '--params-file', str(f)],
                                 automatically_declare_parameters_from_overrides=True)
        try:
            got[name] = {p: node.get_parameter(p) for p in node._parameters}
        finally:
            node.destroy_node()
    b, rb = got['sim_bridge'], got['robot_node']
    assert b['setup'].type_ == Parameter.Type.STRING and b['setup'].value == '6.4_2'
    assert b['mode'].value == 'lockstep' and b['max_steps'].value == 5
    assert b['stdin_commands'].type_ == Parameter.Type.BOOL
    assert rb['prep_steps'].type_ == Parameter.Type.INTEGER
    assert rb['robot_radius'].type_ == Parameter.Type.DOUBLE
    assert abs(rb['robot_radius'].value - 0.08) < 1e-6
    assert rb['lockstep'].value is True and 'policy' not in rb
    assert rb['controller'].value == 'matching-orca'  # in the file, not on command lines
    assert abs(rb['room_size'].value - 2.3) < 1e-6
    assert 'setup' not in rb and 'k_speed' not in b
