"""tending.benchmarl_rust: BenchMARL's MAPPO with tending's own networks as actor and
critic runs, and exports a checkpoint that `tending eval` runs and torch reads back.

A smoke test only (one 800-frame iteration). benchmarl (the `torchrl` extra: torch 2.10,
torchrl 0.11, benchmarl 1.5.2) is not installed by CI: skipped, saying so, without it. The
networks' stepping itself is tested without BenchMARL in test_flat_recurrent.py.
"""


import pytest
from conftest import rust_eval_row

torch = pytest.importorskip(
    "torch", reason="torch is not installed (an optional extra): tending.benchmarl_rust needs it")
pytest.importorskip(
    "benchmarl", reason="benchmarl is not installed (pip install './python[torchrl]'): "
    "tending.benchmarl_rust needs it")


@pytest.mark.parametrize("share_param_critic", [False, True])
def test_mappo_iteration_exports_a_checkpoint_tending_eval_runs(tmp_path, tending_bin, share_param_critic):
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig

    import tending.benchmarl as tb
    from tending import smappo_torch as st
    from tending.benchmarl_rust import RustSmappoConfig, actor_of, export_policy

    torch.set_num_threads(1)
    cfg = ExperimentConfig.get_from_yaml()
    cfg.sampling_device = cfg.train_device = cfg.buffer_device = "cpu"
    cfg.max_n_frames = 800
    cfg.on_policy_collected_frames_per_batch = 800
    cfg.on_policy_n_envs_per_worker = 4
    cfg.on_policy_minibatch_size = 800
    cfg.on_policy_n_minibatch_iters = 1
    cfg.evaluation = False
    cfg.render = False
    cfg.loggers = []
    cfg.create_json = False
    cfg.checkpoint_interval = 0
    cfg.checkpoint_at_end = False
    cfg.save_folder = str(tmp_path)
    algo = MappoConfig.get_from_yaml()
    algo.share_param_critic = share_param_critic
    model = RustSmappoConfig.for_setup("6.4_2")
    # no critic_model_config: BenchMARL's default is a copy of model_config, which it then
    # marks is_critic (the same object for both would turn the policy into a critic)
    exp = Experiment(task=tb.task("6.4_2"), algorithm_config=algo, model_config=model,
                     seed=0, config=cfg)
    before = {k: v.clone() for k, v in actor_of(exp.policy).state_dict().items()}
    exp.run()
    path = tmp_path / "benchmarl.safetensors"
    actor = export_policy(exp, path)
    assert any(not torch.equal(before[k], v) for k, v in actor.state_dict().items()), "no training step"
    back = st.Actor.load(path)
    for k, v in actor.state_dict().items():
        assert torch.equal(v, back.state_dict()[k]), k
    assert rust_eval_row(tending_bin, path, tmp_path)["policy"]
