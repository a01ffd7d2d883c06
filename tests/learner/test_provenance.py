"""Where a run was computed: the code version changes with any file that decides a run,
and works without git; the audit flags arms computed differently."""

from __future__ import annotations

import shutil
from pathlib import Path

from analysis.audit import audit
from analysis.settings import settings_table
from learner import provenance
from learner.config import DQNConfig
from learner.run import RunSpec


def test_the_code_version_changes_with_a_file_under_learner_and_needs_no_git(
    tmp_path: Path,
) -> None:
    for package in provenance.PACKAGES:
        shutil.copytree(provenance.ROOT / package, tmp_path / package,
                        ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    copy = provenance.code_version(tmp_path)
    assert copy == provenance.code_version() and copy.startswith("sha256:")
    assert provenance.commit(tmp_path) is None  # no checkout here
    trainer = tmp_path / "learner" / "trainer.py"
    trainer.write_text(trainer.read_text() + "\n# a change that decides nothing, still new code\n")
    assert provenance.code_version(tmp_path) != copy
    (tmp_path / "sim" / "new_module.py").write_text("X = 1\n")
    assert len({copy, provenance.code_version(tmp_path)}) == 2


def test_a_record_names_the_machine_and_the_numerics() -> None:
    config = DQNConfig(device="cpu", precision="fp32", conv_kernel="avx2", torch_threads=1)
    record = provenance.record(config)
    assert record["code"] == provenance.code_version() and record["torch"]
    assert record["numerics"] == {
        "device": "cpu", "precision": "fp32", "conv_kernel": "avx2", "torch_threads": 1
    }  # fmt: skip


def test_the_audit_flags_arms_computed_by_another_first_layer_kernel() -> None:
    runs = [(1, RunSpec(method="autonomous")), (2, RunSpec(method="random"))]
    here = provenance.record(DQNConfig(precision="fp32", conv_kernel="none"))
    kernel = provenance.record(DQNConfig(precision="fp32", conv_kernel="avx2"))
    same = settings_table(runs, provenance={1: [here], 2: [here]})
    assert audit(same).differ("autonomous", "random") == []
    mixed = settings_table(runs, provenance={1: [here], 2: [here, kernel]})
    assert audit(mixed).differ("autonomous", "random") == ["first-layer kernel"]
    assert mixed.loc[1, "conv_kernel"] == "none + avx2"
    older = {**here, "numerics": {"device": "cpu", "precision": "fp32", "torch_threads": 1}}
    assert settings_table(runs, provenance={1: [older], 2: []}).loc[0, "conv_kernel"] == (
        "not recorded"
    )


def test_the_audit_flags_arms_computed_by_other_code() -> None:
    runs = [(1, RunSpec(method="autonomous")), (2, RunSpec(method="random", config=DQNConfig(
        pretraining_steps=1000)))]  # fmt: skip
    here = provenance.record(DQNConfig())
    elsewhere = {**here, "code": "sha256:0000000000000000"}
    same = settings_table(runs, provenance={1: [here], 2: [here]})
    assert audit(same).differ("autonomous", "random") == []
    mixed = settings_table(runs, provenance={1: [here], 2: [here, elsewhere]})
    assert audit(mixed).differ("autonomous", "random") == ["code version"]
    assert mixed.loc[1, "code_version"] == f"{here['code']} + sha256:0000000000000000"
