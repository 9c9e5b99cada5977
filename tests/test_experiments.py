"""Study grids, skip/resume, and aggregation on synthetic metrics (no training)."""

import csv
import dataclasses
import json
import math

import matplotlib.image as mpimg
import pytest

from hexa_mjx.studies import experiments, study_results


def test_grids_match_the_report(tmp_path):
    main = experiments.grid("main", tmp_path)
    assert len(main) == 10 and {r.config.reward for r in main} == {"goal_directed", "forward_motion"}
    assert sorted({r.seed for r in main}) == [0, 1, 2, 3, 4]
    ablation = experiments.grid("ablation", tmp_path)
    assert [r.config.ablate for r in ablation] == [[], ["contact"], ["height"], ["stability"], ["velocity"]]
    lr = experiments.grid("lr", tmp_path, timesteps=1000, seeds=3)
    assert sorted({r.config.lr for r in lr}) == [1e-4, 3e-4, 1e-3] and len(lr) == 9
    assert all(r.config.num_timesteps == 1000 for r in lr)
    assert lr[0].config.run_dir == str(tmp_path / "lr" / "lr_0.0001-s0")
    assert {r.config.max_contact_points for r in main} == {0}  # every contact slot, as the report's physics
    capped = experiments.grid("ablation", tmp_path, max_contact_points=16)
    assert {r.config.max_contact_points for r in capped} == {16}
    with pytest.raises(ValueError, match="unknown study"):
        experiments.grid("speed", tmp_path)


def test_finished_runs_are_skipped_and_interrupted_ones_resumed(tmp_path):
    runs = experiments.grid("lr", tmp_path, timesteps=1000, seeds=1)
    done, partial, new = runs
    for run, step in ((done, 1024), (partial, 512)):
        run_dir = tmp_path / run.config.run_dir
        (run_dir / "checkpoints" / f"{step:012d}").mkdir(parents=True)
        (run_dir / "config.json").write_text(json.dumps({}))
    assert [experiments.status(r) for r in runs] == ["done", "partial", "new"]
    calls = []
    counts = experiments.run_study(runs, train_fn=calls.append)
    assert counts == {"done": 1, "reused": 0, "partial": 1, "new": 1}
    assert [(c.run_dir, c.resume) for c in calls] == [(partial.config.run_dir, True), (new.config.run_dir, False)]


def test_a_run_identical_to_a_finished_one_is_linked_not_trained(tmp_path):
    main = {(r.condition, r.seed): r for r in experiments.grid("main", tmp_path, timesteps=1000, seeds=1)}
    finished = main[("goal_directed", 0)].config
    (tmp_path / finished.run_dir / "checkpoints" / f"{1024:012d}").mkdir(parents=True)
    (tmp_path / finished.run_dir / "config.json").write_text(json.dumps(dataclasses.asdict(finished)))
    (tmp_path / finished.run_dir / "metrics.jsonl").write_text(json.dumps({"step": 1024}) + "\n")
    lr = experiments.grid("lr", tmp_path, timesteps=1000, seeds=1)
    ablation = experiments.grid("ablation", tmp_path, timesteps=1000, seeds=1)
    calls = []
    assert experiments.run_study(lr, train_fn=calls.append) == {"done": 0, "reused": 1, "partial": 0, "new": 2}
    assert experiments.run_study(ablation, train_fn=calls.append)["reused"] == 1
    # lr 3e-4 and the ablation's "full" are the main study's goal-directed run: linked, not trained.
    assert sorted(c.run_dir for c in calls) == sorted(r.config.run_dir for r in lr + ablation
                                                      if r.condition not in ("lr_0.0003", "full"))
    for linked in (tmp_path / "lr" / "lr_0.0003-s0", tmp_path / "ablation" / "full-s0"):
        assert linked.is_symlink() and linked.resolve() == (tmp_path / finished.run_dir).resolve()
        assert (linked / "metrics.jsonl").is_file()
    assert experiments.run_study(lr, train_fn=calls.append)["done"] == 1  # a linked run counts as finished
    # A larger budget is a different run: the link goes, and the run is trained in its own folder.
    longer = experiments.grid("lr", tmp_path, timesteps=2000, seeds=1)
    assert all(experiments.finished_twin(r) is None for r in longer)
    calls.clear()
    assert experiments.run_study(longer, train_fn=calls.append)["new"] == 3
    assert not (tmp_path / "lr" / "lr_0.0003-s0").exists() and len(calls) == 3
    assert (tmp_path / finished.run_dir / "config.json").is_file()  # the main study's run is untouched


def write_run(root, study, condition, seed, finals):
    run_dir = root / study / f"{condition}-s{seed}"
    run_dir.mkdir(parents=True)
    rows = [{"step": 0, "final_distance": 1.5, "success_rate": 0.0, "episode_return": 0.0, "goal_bonus": 0.0},
            {"step": 1000, **finals}]
    (run_dir / "metrics.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")


def test_aggregation_writes_figures_and_the_right_table(tmp_path):
    for seed, (dist, succ, ret) in enumerate([(0.2, 1.0, 100.0), (0.4, 0.5, 300.0)]):
        write_run(tmp_path, "main", "goal_directed", seed,
                  {"final_distance": dist, "success_rate": succ, "episode_return": ret, "goal_bonus": 10.0})
        write_run(tmp_path, "main", "forward_motion", seed,
                  {"final_distance": 3.0, "success_rate": 0.0, "episode_return": 50.0, "goal_bonus": 0.0})
    write_run(tmp_path, "lr", "lr_0.001", 0, {"final_distance": 0.9, "success_rate": 0.25, "episode_return": 7.0,
                                              "goal_bonus": 1.0})
    paths = study_results.aggregate(tmp_path)
    names = {p.name for p in paths}
    assert {"fig1_main.png", "fig2_seeds.png", "fig3_lr.png", "results.csv", "results.md"} <= names
    assert "fig4_ablation.png" not in names  # no ablation runs, no figure
    assert mpimg.imread(tmp_path / "fig1_main.png").std() > 0.01
    rows = {r["condition"]: r for r in csv.DictReader(open(tmp_path / "results.csv"))}
    gd = rows["goal_directed"]
    assert int(gd["seeds"]) == 2
    assert float(gd["final_distance_mean"]) == pytest.approx(0.3)
    assert float(gd["final_distance_std"]) == pytest.approx(0.1)
    assert float(gd["success_rate_mean"]) == pytest.approx(0.75)
    assert float(gd["episode_return_mean"]) == pytest.approx(200.0)
    assert float(rows["forward_motion"]["final_distance_std"]) == 0.0
    assert "| main | goal_directed | 2 | 1,000 | 0.75 +- 0.25 | 0.300 +- 0.100 | 200.0 +- 100.0 |" in (
        tmp_path / "results.md").read_text()


def test_aggregate_without_runs_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no run folders"):
        study_results.aggregate(tmp_path)


def test_navigation_grids(tmp_path):
    seeds = experiments.grid("navigate", tmp_path, timesteps=1000)
    assert [r.config.seed for r in seeds] == [0, 1, 2, 0, 1, 2]
    assert {(r.config.task, r.config.reward, r.config.update_epochs) for r in seeds} == {("navigate", "navigate", 4)}
    assert [r.config.curriculum_levels for r in seeds] == [0, 0, 0, 5, 5, 5]  # without, then with the curriculum
    assert seeds[0].config.run_dir == str(tmp_path / "seeds-navigate" / "navigate-s0")
    assert seeds[3].config.run_dir == str(tmp_path / "seeds-navigate" / "curriculum-s0")
    ablation = experiments.grid("ablation", tmp_path, timesteps=1000, task="navigate")
    assert {r.config.reward for r in ablation} == {"navigate"}
    assert ablation[1].config.run_dir == str(tmp_path / "ablation-navigate" / "no_contact-s0")
    with pytest.raises(ValueError, match="run it without --task"):
        experiments.grid("main", tmp_path, task="navigate")


def test_energy_grid(tmp_path):
    runs = experiments.grid("energy", tmp_path, timesteps=1000)
    assert sorted((r.config.reward, r.seed) for r in runs) == [(w, s) for w in ("energy", "goal_directed")
                                                              for s in range(3)]
    assert runs[0].config.run_dir == str(tmp_path / "energy" / "goal_directed-s0")
    with pytest.raises(ValueError, match="compares rewards of the report's task"):
        experiments.grid("energy", tmp_path, task="navigate")


def test_gait_table_from_evaluated_runs(tmp_path):
    for condition, seed, cls, cot in (("energy", 0, "tripod", 2.0), ("energy", 1, "irregular", 4.0)):
        path = tmp_path / "energy" / f"{condition}-s{seed}" / "eval" / "metrics.json"
        path.parent.mkdir(parents=True)
        path.write_text(json.dumps({"summary": {"success_rate": 1.0, "gait": {
            "class": cls, "speed": 0.5, "cost_of_transport_median": cot}}}))
    (row,) = study_results.gait_table(tmp_path)
    assert (row["seeds"], row["gait_classes"], row["cot_mean"], row["cot_std"]) == (2, "tripod, irregular", 3.0, 1.0)
    assert "| energy | energy | 2 | 100% | tripod, irregular |" in study_results.write_gait_table([row], tmp_path).read_text()


def test_seed_summary_reports_median_iqr_and_worst_of_eval_and_play_files(tmp_path, capsys):
    from hexa_mjx.studies import seed_summary

    files = []
    for seed, (planar, fall) in enumerate([(0.09, 0.0), (0.11, 0.02), (0.10, 0.01), (0.12, 0.0), (0.08, 0.04)]):
        run = tmp_path / f"vel-s{seed}"
        (run / "eval256").mkdir(parents=True)
        doc = {"config": {"task": "velocity"},
               "summary": {"fall_rate": fall, "success_rate": 0.0, "tracking": {"velocity_rms": planar}}}
        (run / "eval256" / "metrics.json").write_text(json.dumps(doc))
        files.append(run / "eval256" / "metrics.json")
    native = tmp_path / "native.json"  # play.py's layout: the task named at the top
    native.write_text(json.dumps({"task": "navigate", "summary": {"success_rate": 0.5, "fall_rate": 0.0}}))
    seed_summary.main([str(f) for f in files[:5]] + ["--json", str(tmp_path / "s.json")])
    out = json.loads((tmp_path / "s.json").read_text())
    planar = out["summary"]["planar RMS error"]
    assert planar["median"] == pytest.approx(0.10) and planar["worst"] == pytest.approx(0.12)
    assert (planar["q25"], planar["q75"]) == (pytest.approx(0.09), pytest.approx(0.11))
    assert out["summary"]["no fall"]["worst"] == pytest.approx(96.0)  # the fewest episodes without a fall
    assert "success" not in out["summary"]  # a task without goals has no success figure
    assert "| vel-s4 | 0.080 |" in capsys.readouterr().out
    assert seed_summary.figures(json.loads(native.read_text()))["success"] == pytest.approx(50.0)
    with pytest.raises(SystemExit):
        seed_summary.main([str(tmp_path / "missing.json")])


def test_seed_summary_reads_navigations_worst_sector_or_band(tmp_path):
    from hexa_mjx.studies import seed_summary

    navigation = {"sectors": {"+0 deg": {"goals": 30, "success": 1.0}, "+45 deg": {"goals": 29, "success": 0.931},
                              "+90 deg": {"goals": 0, "success": None}},
                  "bands": {"0.5-1.0 m": {"goals": 50, "success": 0.98}}, "goals_per_episode_mean": 8.5}
    doc = {"config": {"task": "navigate"}, "summary": {"success_rate": 0.99, "fall_rate": 0.01,
                                                       "navigation": navigation}}
    row = seed_summary.figures(doc)
    assert row["worst sector or band"] == pytest.approx(93.1)  # the 45-degree sector, not the empty one
    assert row["goals per episode"] == pytest.approx(8.5)
    assert "goals per episode |" in seed_summary.table(["a", "b"], [row, row])
    assert math.isnan(seed_summary.figures({"summary": {"fall_rate": 0.0}})["worst sector or band"])


def test_seed_summary_marks_the_figures_that_miss_the_tasks_targets(tmp_path, capsys):
    from hexa_mjx.studies import seed_summary

    # (fall rate, feet-only share, worst cell's success): seed 1 falls in 3%, seed 2 lacks the cells
    per_seed = [(0.01, 0.995, 1.0), (0.03, 0.995, 1.0), (0.0, 0.999, None)]
    files = []
    for seed, (fall, feet, cell) in enumerate(per_seed):
        navigation = {"sectors": {"+0 deg": {"goals": 9, "success": cell}}} if cell is not None else {}
        files.append(tmp_path / f"nav-s{seed}" / "eval256" / "metrics.json")
        files[-1].parent.mkdir(parents=True)
        files[-1].write_text(json.dumps({"config": {"task": "navigate"}, "summary": {
            "success_rate": 1.0, "fall_rate": fall, "feet_only_steps": feet, "navigation": navigation}}))
    seed_summary.main(["--targets"] + [str(f) for f in files] + ["--json", str(tmp_path / "s.json")])
    out = capsys.readouterr().out
    assert json.loads((tmp_path / "s.json").read_text())["misses"] == {
        "nav-s0": [], "nav-s1": ["no fall"], "nav-s2": ["worst sector or band"]}
    assert "| nav-s0 | 100.00 | 99.00 | 99.50 | 100.00 |" in out
    assert "| nav-s1 | 100.00 | 97.00* | 99.50 | 100.00 |" in out
    assert "| target |  | >= 98.00 | >= 99.00 | >= 95.00 |" in out
    assert "every target on 1 of 3 runs (nav-s0)" in out  # a figure the run lacks counts as a miss
    assert seed_summary.misses({"planar RMS error": 0.11, "no fall": 99.0}, {"planar RMS error": ("<=", 0.10)}) \
        == ["planar RMS error"]
    from hexa_mjx.tasks import TASKS

    known = {name for name, *_ in seed_summary.FIGURES}
    for cls in TASKS.values():  # every task's targets name figures the table has, with a sense and a bound
        assert set(cls.targets) <= known and all(sense in (">=", "<=") for sense, _ in cls.targets.values())
    other = tmp_path / "goal.json"
    other.write_text(json.dumps({"task": "goal", "summary": {"success_rate": 1.0, "fall_rate": 0.0}}))
    with pytest.raises(SystemExit):  # two tasks, and the report's task has no targets here
        seed_summary.main(["--targets", str(files[0]), str(other)])
    assert "--targets needs evaluations of one task with targets (drive, navigate, velocity)" in capsys.readouterr().err


def seed_files(tmp_path, pattern: str, per_seed: list) -> list:
    """One JSON file per seed at tmp_path / pattern.format(seed), each holding that seed's rows."""
    files = []
    for seed, rows in enumerate(per_seed):
        files.append(tmp_path / pattern.format(seed))
        files[-1].parent.mkdir(parents=True)
        files[-1].write_text(json.dumps(rows))
    return files


def test_seed_summary_of_generalist_batteries(tmp_path, capsys):
    from hexa_mjx.studies import seed_summary

    # Three seeds, two conditions: completions 100/90/80% (all meet) and 50/100/75% (the first misses).
    files = seed_files(tmp_path, "gen-s{}/battery.json", [
        [{"group": "flat", "condition": "flat, intact", "path_completed_rate": flat, "fall_rate": 0.0,
          "meets_target": True},
         {"group": "one leg", "condition": "leg 1 limp", "path_completed_rate": leg, "fall_rate": 0.0,
          "meets_target": leg_met}]
        for flat, leg, leg_met in [(1.0, 0.5, False), (0.9, 1.0, True), (0.8, 0.75, True)]])
    seed_summary.main(["--battery", *map(str, files)])
    out = capsys.readouterr().out
    assert "| flat, intact | 100% | 90% | 80% | 90% | 85 to 95% | 80% | 3 of 3 |" in out
    assert "| leg 1 limp | 50%* | 100% | 75% | 75% | 62 to 88% | 50% | 2 of 3 |" in out
    assert "1 of 2 conditions met by every seed" in out
    other = tmp_path / "other.json"  # a battery of other conditions
    other.write_text(json.dumps([{"condition": "stairs 5 cm", "path_completed_rate": 1.0, "meets_target": True}] * 2))
    with pytest.raises(SystemExit):
        seed_summary.main(["--battery", str(files[0]), str(other)])
    evaluation = tmp_path / "eval.json"  # an eval.py file is not a battery
    evaluation.write_text(json.dumps({"summary": {"success_rate": 1.0}}))
    with pytest.raises(SystemExit):
        seed_summary.main(["--battery", str(files[0]), str(evaluation)])


def test_seed_summary_of_leg_failure_sweeps(tmp_path, capsys):
    from hexa_mjx.studies import seed_summary

    # Three seeds: with leg 1 failed, one meets the target (90% at 70%), one misses on success and one
    # on speed; with legs 1 and 6, one misses 75% success. Intact has no target.
    files = seed_files(tmp_path, "legfail-s{}/sweep.json", [
        [{"failed_legs": [], "success_rate": 1.0, "speed_share_of_intact": 1.0},
         {"failed_legs": [1], "success_rate": leg, "speed_share_of_intact": share},
         {"failed_legs": [1, 6], "success_rate": pair, "speed_share_of_intact": None}]
        for leg, share, pair in [(0.95, 0.80, 0.80), (0.85, 0.75, 0.70), (1.0, 0.65, 0.90)]])
    seed_summary.main(["--legs", *map(str, files)])
    out = capsys.readouterr().out
    assert "| 1 | 95% / 80.0% | 85% / 75.0%* | 100% / 65.0%* | 95%, 90 to 98%, 85% | 75%, 70 to 78%, 65% | 1 of 3 |" in out
    assert "| 1 + 6 | 80% / - | 70% / -* | 90% / - | 80%, 75 to 85%, 70% | - | 2 of 3 |" in out
    assert "| none | " in out and "0 of 2 failures met by every seed" in out
    other = tmp_path / "other.json"  # a sweep of other legs
    other.write_text(json.dumps([{"failed_legs": [2], "success_rate": 1.0}] * 3))
    with pytest.raises(SystemExit):
        seed_summary.main(["--legs", str(files[0]), str(other)])
    battery = tmp_path / "battery.json"  # a generalist battery is not a sweep
    battery.write_text(json.dumps([{"condition": "leg 1 limp", "path_completed_rate": 1.0, "meets_target": True}]))
    for wrong in (["--legs", str(files[0]), str(battery)], ["--legs", "--battery", str(files[0])]):
        with pytest.raises(SystemExit):
            seed_summary.main(wrong)
