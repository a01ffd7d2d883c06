"""`ideeprl train`: train one learner from the command line.

Writes into --out: steps.csv and episodes.csv (the records, columns as documented in
`learner.records`, a step's Q-values under its task's action names: `q_grab`, ...),
learning_curve.png, config.json, and checkpoint.pt (every --checkpoint-every training
episodes, on Ctrl-C, and at the end). `--resume CHECKPOINT`
continues a run exactly where its checkpoint left it, with the advisor and strategy
stored in the checkpoint.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from cli.commands.common import add_deprecated, add_set_option, given_values
from learner.config import DQNConfig
from learner.fields import add_arguments as add_spec_arguments
from learner.fields import nest
from learner.records import EpisodeRecord, StepRecord
from learner.run import RunSpec, declared


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
    run = parser.add_argument_group(
        "the run", "every field of learner.run.RunSpec, one flag each (or --set FIELD=VALUE)"
    )
    add_spec_arguments(run, declared())
    add_deprecated(parser)
    add_set_option(parser, "set any field of the run by its name")
    parser.add_argument("--checkpoint-every", type=int, default=25, metavar="EPISODES")
    parser.add_argument(
        "--resume",
        type=Path,
        metavar="CHECKPOINT",
        help="continue a run; its settings come from the checkpoint (only --episodes and "
        "--out may change)",
    )
    parser.add_argument(
        "--override-numerics",
        action="store_true",
        help="resume on this machine's numerics although the run was pinned to others it "
        "cannot honour",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def train(args: argparse.Namespace) -> int:
    try:
        spec, resumed_step = run_spec(args)
        spec = spec.validate()
    except (ValueError, FileNotFoundError) as error:
        print(f"ideeprl train: error: {error}", file=sys.stderr)
        return 2
    if spec.method == "human":
        print("ideeprl train: error: a human run needs the server (ideeprl serve)", file=sys.stderr)
        return 2
    from learner.recording import CsvRecorder, plot_learning_curve, training_curve

    config, settings = spec.config, spec.to_json()
    out = args.out or (args.resume.parent if args.resume else _default_out())
    recorder = CsvRecorder(out, resume_from_step=resumed_step, actions=spec.the_task.action_names)
    # Bars only for a person at a terminal, never into a pipe or a log file.
    progress = Progress(config, resumed_step, disable=args.no_progress or not sys.stderr.isatty())
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
    curve = training_curve(recorder.episodes_path)
    rewards = curve.rewards
    label = "DeepRL" if not spec.advised else f"{spec.method}-IDeepRL"
    plot = plot_learning_curve(rewards, curve.epsilons, out / "learning_curve.png", label)
    print(
        f"{len(rewards)} training episodes, {trainer.global_step} steps in "
        f"{time.perf_counter() - started:.0f} s; R_T = {sum(rewards):.2f}, "
        f"last 10 episodes' mean reward {sum(rewards[-10:]) / max(1, len(rewards[-10:])):.2f}\n"
        f"wrote {recorder.steps_path}, {recorder.episodes_path}, {plot}, {checkpoint}"
    )
    return 0


def run_spec(args: argparse.Namespace) -> tuple[RunSpec, int | None]:
    """The run the arguments describe, validated and pinned on this machine; or the
    checkpoint's when resuming (then only --episodes may change, and numerics this machine
    cannot honour are refused unless --override-numerics), and the global step a resumed run
    stands at."""
    declaration = declared()
    values = given_values(args, declaration)
    if args.resume:
        spec, global_step = declaration.from_checkpoint(args.resume)
        changed = sorted(set(values) - {"episodes"})
        if changed:
            raise ValueError(
                "a resumed run keeps its settings; only --episodes may change, not "
                + ", ".join("--" + name.replace("_", "-") for name in changed)
            )
        if "episodes" in values:
            spec = spec.with_values({"episodes": values["episodes"]})
        problem = spec.numerics_problem()
        if problem and not args.override_numerics:
            raise ValueError(f"cannot resume {args.resume}: {problem}")
        if problem:
            spec = spec.repinned()
            print(f"warning: numerics overridden ({problem})", file=sys.stderr)
        return spec.validate().pinned(), global_step
    return declaration.from_json(nest(values, declaration)).validate().pinned(), None


def _checkpoint_due(finished: EpisodeRecord | None, every: int) -> bool:
    """After every `every`-th training episode (never with 0)."""
    if finished is None or finished.stage != "train" or every <= 0:
        return False
    return finished.episode % every == 0


def _default_out() -> Path:
    return Path("study_data") / "runs" / time.strftime("train-%Y%m%d-%H%M%S")


class Progress:
    """Progress bars: pretraining steps, then training episodes with epsilon and reward."""

    def __init__(self, config: DQNConfig, resumed_step: int | None, disable: bool = False) -> None:
        self.config = config
        self.disable = disable
        done = resumed_step or 0
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
        if record.stage != "train":
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
        if record.stage != "train" or self.training is None:
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
