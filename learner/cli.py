"""`ideeprl train` (and `python -m learner train`): train one learner from the command line.

Writes into --out: steps.csv and episodes.csv (the records, columns as documented in
`learner.records`), learning_curve.png, config.json, and checkpoint.pt (every
--checkpoint-every training episodes, on Ctrl-C, and at the end). `--resume CHECKPOINT`
continues a run exactly where its checkpoint left it, with the advisor and strategy
stored in the checkpoint.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from learner.checkpoint import read_checkpoint
from learner.config import PRESETS, DQNConfig
from learner.records import EpisodeRecord, StepRecord
from learner.run import ADVISORS, MOTIONS, STRATEGY_OPTIONS, RunSpec
from learner.strategies import STRATEGY_NAMES
from sim.rewards import REWARD_SCHEMES
from sim.scenario import ScenarioOptions

ADVISOR_CHOICES = tuple(name for name in ADVISORS if name != "human")


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "train",
        help="train one learner (autonomous, or advised) and write its records",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(parser)
    parser.set_defaults(func=train)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", type=Path, help="output folder (default: study_data/runs/train-DATE)"
    )
    parser.add_argument("--preset", choices=PRESETS, default="paper", help="config preset")
    parser.add_argument("--episodes", type=int, help="training episodes (default 300)")
    parser.add_argument(
        "--seed", type=int, default=0, help="fixes scene, network, memory, exploration"
    )
    parser.add_argument("--advisor", choices=ADVISOR_CHOICES, default="none")
    parser.add_argument(
        "--advisor-checkpoint", type=Path, help="trained learner for --advisor agent"
    )
    parser.add_argument("--error-rate", type=float, default=0.0, help="oracle's wrong-advice rate")
    parser.add_argument("--strategy", choices=STRATEGY_NAMES, default="early")
    parser.add_argument("--budget", type=int, help="advice budget (default: advice_budget, 100)")
    parser.add_argument(
        "--interval", type=int, default=2, help="alternating: advise every Nth step"
    )
    parser.add_argument("--threshold", type=float, default=0.1, help="importance: Q-value spread")
    parser.add_argument("--motion", choices=MOTIONS, default="fast")
    parser.add_argument("--sort-rule", default="color", help="color, shape, or a JSON object map")
    add_scenario_arguments(parser)
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a config field (VALUE as JSON, else a string); repeatable",
    )
    parser.add_argument("--device", help="auto, cpu, cuda, cuda:N (default: the config's, auto)")
    parser.add_argument("--threads", type=int, help="torch threads (default: half the cores, 1-4)")
    parser.add_argument("--checkpoint-every", type=int, default=25, metavar="EPISODES")
    parser.add_argument(
        "--resume",
        type=Path,
        metavar="CHECKPOINT",
        help="continue a run; its settings come from the checkpoint (only --episodes, "
        "--device, --threads and --out may change)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    """The scenario's options (`sim.ScenarioOptions`); `scenario_options(args)` reads them."""
    parser.add_argument(
        "--reward-scheme",
        choices=REWARD_SCHEMES,
        default="paper",
        help="what a step without a placement costs: the paper's text (default), or the "
        "authors' autonomous / interactive scripts",
    )
    parser.add_argument(
        "--grasp-failure-rate", type=float, default=0.0, help="chance a grab comes back empty"
    )
    parser.add_argument(
        "--knock-off-rate",
        type=float,
        default=0.0,
        help="chance a grab knocks another object off the center table",
    )


def scenario_options(args: argparse.Namespace) -> dict[str, Any]:
    """The scenario options the arguments give, checked (`ValueError` otherwise)."""
    return ScenarioOptions(
        args.reward_scheme, args.grasp_failure_rate, args.knock_off_rate
    ).to_dict()


def train(args: argparse.Namespace) -> int:
    try:
        spec, resume_state = run_spec(args)
        spec = spec.validate()
    except (ValueError, FileNotFoundError) as error:
        print(f"ideeprl train: error: {error}", file=sys.stderr)
        return 2
    from learner.recording import CsvRecorder, plot_learning_curve, read_episodes

    config, settings = spec.config, spec.settings()
    out = args.out or (args.resume.parent if args.resume else _default_out())
    resumed_step = resume_state["global_step"] if resume_state else None
    recorder = CsvRecorder(out, resume_from_step=resumed_step)
    # Bars only for a person at a terminal, never into a pipe or a log file.
    progress = Progress(config, resume_state, disable=args.no_progress or not sys.stderr.isatty())
    trainer, _env = spec.build([recorder, progress])
    if args.resume:
        trainer.load_checkpoint(args.resume)
    (out / "config.json").write_text(json.dumps(config.to_dict(), indent=2) + "\n")
    checkpoint = out / "checkpoint.pt"
    started = time.perf_counter()
    try:
        while not trainer.done:
            trainer.step()
            if _checkpoint_due(trainer.episode_record, args.checkpoint_every):
                trainer.save_checkpoint(checkpoint, settings)
    except KeyboardInterrupt:
        trainer.save_checkpoint(checkpoint, settings)
        progress.close()
        recorder.close()
        print(f"\nstopped at step {trainer.global_step}; continue with --resume {checkpoint}")
        return 130
    finally:
        progress.close()
        recorder.close()
    trainer.save_checkpoint(checkpoint, settings)
    rows = [row for row in read_episodes(recorder.episodes_path) if row["phase"] == "train"]
    rewards = [row["collected_reward"] for row in rows]
    label = "DeepRL" if spec.advisor == "none" else f"{spec.advisor}-IDeepRL"
    plot = plot_learning_curve(
        rewards, [row["epsilon"] for row in rows], out / "learning_curve.png", label
    )
    print(
        f"{len(rewards)} training episodes, {trainer.global_step} steps in "
        f"{time.perf_counter() - started:.0f} s; R_T = {sum(rewards):.2f}, "
        f"last 10 episodes' mean reward {sum(rewards[-10:]) / max(1, len(rewards[-10:])):.2f}\n"
        f"wrote {recorder.steps_path}, {recorder.episodes_path}, {plot}, {checkpoint}"
    )
    return 0


def run_spec(args: argparse.Namespace) -> tuple[RunSpec, dict[str, Any] | None]:
    """The run the arguments describe, or the checkpoint's when resuming (then only
    --episodes, --device, --threads may change), and where a resumed run stands."""
    runtime: dict[str, Any] = {}
    if args.episodes is not None:
        runtime["episodes"] = args.episodes
    if args.device is not None:
        runtime["device"] = args.device
    if args.threads is not None:
        runtime["torch_threads"] = args.threads
    if args.resume:
        state = read_checkpoint(args.resume)
        config = DQNConfig.from_dict({**state["config"], **runtime})
        settings = dict(state["metadata"])
        if "advisor" not in settings:
            raise ValueError(f"{args.resume} was not written by ideeprl train")
        return RunSpec.from_settings(settings, config), {"global_step": int(state["global_step"])}
    overrides = dict(_parse_assignment(item) for item in args.set)
    config = DQNConfig.preset(args.preset, **{**overrides, **runtime})
    given = {"interval": args.interval, "threshold": args.threshold}
    if args.advisor == "agent" and not args.advisor_checkpoint:
        raise ValueError("--advisor agent needs --advisor-checkpoint PATH")
    spec = RunSpec(
        seed=args.seed,
        config=config,
        preset=args.preset,
        advisor=args.advisor,
        advisor_checkpoint=str(args.advisor_checkpoint) if args.advisor_checkpoint else None,
        error_rate=args.error_rate,
        strategy=args.strategy,
        # the flags have defaults; each strategy takes the ones it knows
        strategy_options={k: v for k, v in given.items() if k in STRATEGY_OPTIONS[args.strategy]},
        budget=args.budget,
        motion=args.motion,
        sort_rule=_parse_json(args.sort_rule),
        scenario=ScenarioOptions(**scenario_options(args)),
    )
    return spec, None


def _checkpoint_due(finished: EpisodeRecord | None, every: int) -> bool:
    """After every `every`-th training episode (never with 0)."""
    if finished is None or finished.phase != "train" or every <= 0:
        return False
    return finished.episode % every == 0


def _parse_assignment(item: str) -> tuple[str, Any]:
    name, sep, value = item.partition("=")
    if not sep or not name:
        raise ValueError(f"--set takes FIELD=VALUE, got {item!r}")
    return name.strip(), _parse_json(value)


def _parse_json(value: str) -> Any:
    try:
        return json.loads(value)
    except json.JSONDecodeError:
        return value


def _default_out() -> Path:
    return Path("study_data") / "runs" / time.strftime("train-%Y%m%d-%H%M%S")


class Progress:
    """Progress bars: pretraining steps, then training episodes with epsilon and reward."""

    def __init__(
        self, config: DQNConfig, resume_state: dict[str, Any] | None, disable: bool = False
    ) -> None:
        self.config = config
        self.disable = disable
        done = resume_state["global_step"] if resume_state else 0
        self.pretraining: Any = tqdm(
            total=config.pretraining_steps,
            initial=min(done, config.pretraining_steps),
            desc="pretraining",
            unit="step",
            disable=disable or done >= config.pretraining_steps,
        )
        self.training: Any = None
        self.rewards: list[float] = []

    def on_step(self, record: StepRecord) -> None:
        if record.phase != "train":
            self.pretraining.update(1)
        elif self.training is None:
            self.pretraining.close()
            self.training = tqdm(
                total=self.config.episodes,
                initial=record.episode - 1,
                desc="training",
                unit="episode",
                disable=self.disable,
            )

    def on_episode(self, record: EpisodeRecord) -> None:
        if record.phase != "train" or self.training is None:
            return
        self.rewards.append(record.collected_reward)
        recent = self.rewards[-10:]
        self.training.set_postfix(
            epsilon=f"{record.epsilon:.3f}",
            reward=f"{record.collected_reward:.2f}",
            mean10=f"{sum(recent) / len(recent):.2f}",
            refresh=False,
        )
        self.training.update(1)

    def close(self) -> None:
        self.pretraining.close()
        if self.training is not None:
            self.training.close()


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m learner")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    register(subparsers)
    args = parser.parse_args(argv)
    return int(args.func(args) or 0)
