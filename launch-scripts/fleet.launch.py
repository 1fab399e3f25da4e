"""Launch a simulated tending fleet: one sim_bridge and N robot_node, one per robot.

    ros2 launch tending fleet.launch.py setup:=6.4_2 seed:=0
    ros2 launch tending fleet.launch.py setup:=10.6_4 robots:=8 policy:=/path/to/policy.safetensors

Launch arguments:
    setup          scenario name N.M_K (agents.machines_storages), passed to sim_bridge
    robots         number of robot_node processes; default: N of `setup`
    seed           simulator seed, passed to sim_bridge
    policy         checkpoint (safetensors) for every robot_node; empty: greedy controller
    controller     `greedy`, `greedy-orca`, `matching-orca` or `policy`; empty: robot_node
                   decides (policy if a path is given)
    params_file    a ROS 2 parameters file for every node, e.g. the `fleet.yaml` that
                   `tending fleet` writes (sizes, speeds, timeouts, the ORCA filter's
                   margins as orca_clearance, orca_rest_clearance, orca_obstacle_horizon:
                   robot_node's one way in for them; per-node sections); the launch
                   arguments above override it
    use_sim_time   robot nodes tick on the bridge's /clock (true) or the wall clock
    bridge         `true` to start sim_bridge (false: robots only, e.g. on hardware)

Robot i runs in namespace /robot_i (robot_node's identity), so its topics are
/robot_i/pose, /robot_i/has_part, /robot_i/cmd_vel as in the DESIGN.md contract.
"""

import os

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'tending'
CONTROLLERS = ('', 'greedy', 'greedy-orca', 'matching-orca', 'policy')

ARGUMENTS = [
    ('setup', '6.4_2', 'scenario N.M_K (agents.machines_storages)'),
    ('robots', '', 'number of robots; empty: N of setup'),
    ('seed', '0', 'simulator seed'),
    ('policy', '', 'policy checkpoint for every robot; empty: greedy controller'),
    ('controller', '', 'greedy, greedy-orca, matching-orca or policy; empty: robot_node default'),
    ('params_file', '', 'ROS 2 parameters file for every node (tending fleet writes fleet.yaml)'),
    ('use_sim_time', 'true', 'robot nodes follow /clock from sim_bridge'),
    ('bridge', 'true', 'start sim_bridge'),
]


def parse_bool(name, text):
    t = text.strip().lower()
    if t in ('true', '1', 'yes', 'on'):
        return True
    if t in ('false', '0', 'no', 'off'):
        return False
    raise ValueError(f'launch argument {name}:={text!r}: expected true or false')


def robots_of_setup(setup):
    """`6.4_2` -> 6 (agents.machines_storages)."""
    head = setup.strip().split('.', 1)[0]
    if not head.isdigit() or int(head) < 1:
        raise ValueError(f'launch argument setup:={setup!r}: expected N.M_K, e.g. 6.4_2')
    return int(head)


def fleet_actions(values):
    """The nodes for the given launch-argument values (a dict of strings)."""
    setup = values['setup'].strip()
    seed_text = values['seed'].strip()
    try:
        seed = int(seed_text)
    except ValueError:
        raise ValueError(f'launch argument seed:={seed_text!r}: expected an integer') from None
    robots_text = values['robots'].strip()
    if robots_text:
        if not robots_text.isdigit() or int(robots_text) < 1:
            raise ValueError(f'launch argument robots:={robots_text!r}: expected an integer >= 1')
        n = int(robots_text)
    else:
        n = robots_of_setup(setup)
    use_sim_time = parse_bool('use_sim_time', values['use_sim_time'])
    policy = values['policy'].strip()
    controller = values['controller'].strip()
    if controller not in CONTROLLERS:
        raise ValueError(f'launch argument controller:={controller!r}: expected one of '
                         + ', '.join(c for c in CONTROLLERS if c))
    # the file first: ROS 2 applies `parameters` in order, so the arguments override it
    params_file = values.get('params_file', '').strip()
    if params_file and not os.path.isfile(params_file):
        raise ValueError(f'launch argument params_file:={params_file!r}: no such file')
    first = [params_file] if params_file else []

    actions = []
    if parse_bool('bridge', values['bridge']):
        actions.append(Node(
            package=PACKAGE,
            executable='sim_bridge',
            name='sim_bridge',
            output='screen',
            parameters=first + [{'setup': setup, 'seed': seed}],
        ))
    robot_params = {'use_sim_time': use_sim_time}
    if policy:
        robot_params['policy'] = policy
    if controller:
        robot_params['controller'] = controller
    for i in range(n):
        actions.append(Node(
            package=PACKAGE,
            executable='robot_node',
            name='robot_node',
            namespace=f'robot_{i}',
            output='screen',
            parameters=first + [dict(robot_params)],
        ))
    return actions


def _launch_setup(context, *args, **kwargs):
    values = {name: LaunchConfiguration(name).perform(context) for name, _, _ in ARGUMENTS}
    return fleet_actions(values)


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=doc)
         for name, default, doc in ARGUMENTS]
        + [OpaqueFunction(function=_launch_setup)]
    )
