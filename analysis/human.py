"""The participant is the unit: an online study's visits by condition, their flow, each
participant's measures and the tests between conditions, from the tables an export holds
(`sessions`, `advice`, `feedback`, `check`, `questionnaire`, `scales`), or the same read
from the database.

Nothing here waits for a learner: a completed visit's advice, decision times, check and
questionnaire are what the participant did, whether or not the learner they advised has
finished its episodes.

- The flow counts every visit (a session with a condition) by its `outcome`: arrived,
  declined, consented (`consented_at`), excluded by the check, timed out, completed, and
  those still under way (no outcome yet).
- A participant's turns are their evaluative ratings where their session has any
  (`feedback`: Good and Bad on the learner's own actions), else their advice. Their
  measures are those of a completed visit: the turns they answered (advice given, or
  ratings given), the accuracy of those answers against the task's correct action where
  the table records one (`correct_action`, and `correct_actions` where other actions are
  as right, as the grid world's equally short moves are: advice is right when it names
  one of them; a rating is right when it says good of one of them or bad of another; where
  none is recorded there is no accuracy, and the report says so), the median of their decision
  times, their questionnaire's scales (`scales`: NASA-TLX raw, trust), and every numeric
  item (NASA-TLX subscales, trust items, the researcher's own).
- The check's rates are over every participant who took it: passed at the first try, and
  passed at all (the others were excluded).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
import pandas as pd

from analysis.between import Tested, fisher, holm, mann_whitney, welch
from analysis.finished import is_finished
from tasks import actions_of_text

FLOW = ("arrived", "declined", "consented", "excluded", "timed_out", "completed", "under_way")
"""The flow's counts per condition, in the order a CONSORT diagram reads them."""
OUTCOMES = {"declined", "excluded", "timed_out", "completed"}
"""The outcomes a visit ends with (`sessions.outcome`)."""
PERSON = "human"
"""The advisor or evaluator of a participant's own advice or ratings (as the server
stores it: `study.services.feedback.PERSON`)."""
FEEDBACK_COLUMNS = ["session_id", "evaluator", "action", "judgement", "decision_time_s"]
"""The feedback table's columns the section reads (and `correct_action`, `correct_actions`
where recorded)."""
TURN_COLUMNS = ["session_id", "gave", "answered", "decision_time_s", "correct"]
"""One row per turn (`turns`): `gave` advice or ratings, `answered` (an answer was
given), its decision time, `correct` 1.0 or 0.0 (NaN: not known)."""


@dataclass(frozen=True)
class Visits:
    """What the participants of an online study did, one table each as the export has it."""

    sessions: pd.DataFrame
    """session_id, condition, outcome, consented_at, status (every visit, any outcome)."""
    advice: pd.DataFrame
    """session_id, advisor, action, decision_time_s, [correct_action, correct_actions]."""
    check: pd.DataFrame
    """session_id, attempt, question, correct."""
    questionnaire: pd.DataFrame
    """session_id, instrument, item, value_number."""
    scales: pd.DataFrame
    """session_id, scale, score."""
    feedback: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=FEEDBACK_COLUMNS))
    """session_id, evaluator, action, judgement (+1 good, -1 bad, NaN no answer),
    decision_time_s, [correct_action, correct_actions]: the ratings of evaluative feedback."""

    @property
    def visits(self) -> pd.DataFrame:
        """The sessions with a condition (an online study's visits)."""
        table = self.sessions
        return table[table["condition"].notna() & (table["condition"] != "")]

    @property
    def conditions(self) -> list[str]:
        return list(dict.fromkeys(sorted(self.visits["condition"].astype(str))))

    @property
    def completed(self) -> pd.DataFrame:
        visits = self.visits
        return visits[visits["outcome"] == "completed"]

    @property
    def rated(self) -> set[int]:
        """Sessions whose turns are ratings (they have feedback rows)."""
        return {int(i) for i in self.feedback["session_id"]}

    @property
    def advised_by_people(self) -> set[int]:
        """Sessions whose advice or ratings came from a participant."""
        advice, feedback = self.advice, self.feedback
        return {
            *(int(i) for i in advice.loc[advice["advisor"] == PERSON, "session_id"]),
            *(int(i) for i in feedback.loc[feedback["evaluator"] == PERSON, "session_id"]),
        }

    @property
    def correct_action_recorded(self) -> bool:
        """Whether the turns' table records the task's correct action: the advice's, or
        the feedback's for rated sessions."""
        advice = self.advice[~self.advice["session_id"].isin(self.rated)]
        return any(
            "correct_action" in table and table["correct_action"].notna().any()
            for table in (advice, self.feedback)
        )


def learners_finished(visits: Visits) -> str:
    """The report's first line: how many of the completed visits' learners have finished,
    and what that means for the two sections."""
    done = visits.completed
    finished = sum(is_finished(status) for status in done["status"])
    return (
        f"Learners finished: {finished} of the {len(done)} completed visits' learners; "
        "the participants' section covers every completed visit, the learners' R_T only "
        "the finished ones."
    )


def flow(visits: Visits) -> pd.DataFrame:
    """Per condition: the counts of `FLOW` (one row a condition)."""
    rows = []
    for condition in visits.conditions:
        group = visits.visits[visits.visits["condition"] == condition]
        outcome = group["outcome"]
        rows.append(
            {
                "condition": condition,
                "arrived": len(group),
                "declined": int((outcome == "declined").sum()),
                "consented": int(group["consented_at"].notna().sum()),
                "excluded": int((outcome == "excluded").sum()),
                "timed_out": int((outcome == "timed_out").sum()),
                "completed": int((outcome == "completed").sum()),
                "under_way": int((~outcome.isin(list(OUTCOMES))).sum()),
            }
        )
    return pd.DataFrame(rows, columns=["condition", *FLOW])


def _check_results(visits: Visits) -> pd.DataFrame:
    """Per participant who took the check: passed at the first try, passed at all."""
    check = visits.check
    if check.empty:
        return pd.DataFrame(columns=["session_id", "first_try", "passed"])
    tries = check.groupby(["session_id", "attempt"])["correct"].all().reset_index()
    first = tries.sort_values("attempt").groupby("session_id")["correct"].first()
    passed = tries.groupby("session_id")["correct"].any()
    return pd.DataFrame({"first_try": first, "passed": passed}).reset_index()


def items(visits: Visits) -> pd.DataFrame:
    """Completed visits' numeric questionnaire answers, one column per instrument/item."""
    answers = visits.questionnaire
    answers = answers[
        answers["session_id"].isin(visits.completed["session_id"]) & answers["value_number"].notna()
    ]
    if answers.empty:
        return pd.DataFrame(index=pd.Index([], name="session_id"))
    keys = answers["instrument"].astype(str) + "/" + answers["item"].astype(str)
    wide = answers.assign(key=keys).pivot(index="session_id", columns="key", values="value_number")
    return wide.astype(float)


def _right(table: pd.DataFrame) -> pd.Series:
    """1.0 where the row's action is right, 0.0 where not, NaN where the row records no
    correct action: one of its `correct_actions` where it lists them (the grid world's moves
    equally near the goal), else its `correct_action`."""
    if "correct_action" not in table:
        return pd.Series(np.nan, index=table.index)
    action = table["action"].astype(float)
    right = (action == table["correct_action"].astype(float)).astype(float)
    if "correct_actions" in table:
        listed = table["correct_actions"].map(lambda t: t if isinstance(t, str) and t else None)
        sets = listed.dropna().map(actions_of_text)
        right.loc[sets.index] = [
            float(a in s) for a, s in zip(action[sets.index], sets, strict=True)
        ]
    return right.where(table["correct_action"].notna())


def turns(visits: Visits) -> pd.DataFrame:
    """Every turn of every session (`TURN_COLUMNS`): its ratings where it has any, else
    its advice. A rating is right when it says good (judgement > 0) of the correct action
    or bad (< 0) of another; a judgement of 0 says neither, and is not scored."""
    advice = visits.advice[~visits.advice["session_id"].isin(visits.rated)]
    action = advice["action"].astype(float)
    advised = pd.DataFrame(
        {
            "session_id": advice["session_id"],
            "gave": "advice",
            "answered": action.notna(),
            "decision_time_s": advice["decision_time_s"].astype(float),
            "correct": _right(advice),
        }
    )
    feedback = visits.feedback
    judgement = feedback["judgement"].astype(float)
    right = _right(feedback)
    scored = judgement.notna() & (judgement != 0) & right.notna()
    correct = ((judgement > 0) == (right == 1)).astype(float).where(scored)
    rated = pd.DataFrame(
        {
            "session_id": feedback["session_id"],
            "gave": "ratings",
            "answered": judgement.notna(),
            "decision_time_s": feedback["decision_time_s"].astype(float),
            "correct": correct,
        }
    )
    frames = [f for f in (advised, rated) if len(f)]
    if not frames:
        return pd.DataFrame(columns=TURN_COLUMNS)
    return pd.concat(frames, ignore_index=True)[TURN_COLUMNS]


def participants(visits: Visits) -> pd.DataFrame:
    """One row per completed visit: session_id, condition, gave (`advice` or `ratings`:
    their turns), advice (the turns they answered: advice given, or ratings given),
    accuracy (NaN where no correct action is recorded), median_decision_s, the check's
    first_try and passed, one column per scale score (`scale_nasa_tlx`, `scale_trust`)."""
    done = visits.completed[["session_id", "condition"]].copy()
    done["gave"] = ["ratings" if i in visits.rated else "advice" for i in done["session_id"]]
    mine = turns(visits)
    given = mine[mine["session_id"].isin(done["session_id"]) & mine["answered"].astype(bool)]
    done["advice"] = done["session_id"].map(given.groupby("session_id").size()).fillna(0)
    done["advice"] = done["advice"].astype(int)
    known = given[given["correct"].notna()]
    accuracy = known.groupby("session_id")["correct"].mean()
    done["accuracy"] = done["session_id"].map(accuracy).astype(float)
    times = given[given["decision_time_s"].notna()]
    median = times.groupby("session_id")["decision_time_s"].median()
    done["median_decision_s"] = done["session_id"].map(median)
    check = _check_results(visits).set_index("session_id")
    done["first_try"] = done["session_id"].map(check["first_try"])
    done["passed"] = done["session_id"].map(check["passed"])
    for scale, group in visits.scales.groupby("scale"):
        done[f"scale_{scale}"] = done["session_id"].map(group.set_index("session_id")["score"])
    return done.reset_index(drop=True)


def check_rates(visits: Visits) -> pd.DataFrame:
    """Per condition: participants who took the check, passed at the first try, passed."""
    results = _check_results(visits)
    condition = visits.visits.set_index("session_id")["condition"]
    results = results.assign(condition=results["session_id"].map(condition))
    rows = []
    for name in visits.conditions:
        group = results[results["condition"] == name]
        rows.append(
            {
                "condition": name,
                "took": len(group),
                "first_try": int(group["first_try"].astype(bool).sum()),
                "passed": int(group["passed"].astype(bool).sum()),
            }
        )
    return pd.DataFrame(rows, columns=["condition", "took", "first_try", "passed"])


def given_words(gave: set[str]) -> str:
    """What the participants' answered turns are called: advice given, ratings given, or
    both where some gave advice and others ratings."""
    if gave == {"ratings"}:
        return "ratings given"
    return "advice or ratings given" if "ratings" in gave else "advice given"


TEST_COLUMNS = [
    "family", "measure", "condition_a", "condition_b", "test", "n_a", "n_b", "statistic",
    "p", "p_holm", "significant", "effect", "estimate", "low", "high", "no_test",
]  # fmt: skip


def _row(family: str, measure: str, a: str, b: str, tested: Tested) -> dict[str, object]:
    return {"family": family, "measure": measure, "condition_a": a, "condition_b": b,
            **tested.__dict__}  # fmt: skip


def between_conditions(visits: Visits, alpha: float) -> pd.DataFrame:
    """Every pair of conditions on every measure (`TEST_COLUMNS`), Holm's correction within
    each family: `advice` (Welch's t: advice given, accuracy, decision times on a log
    scale), `scales` (Welch's t), `items` (Mann-Whitney's U: each Likert item and NASA-TLX
    subscale), `rates` (Fisher's exact: the check at the first try, the check, completion
    among those who consented)."""
    people = participants(visits)
    answered = items(visits)
    rates = check_rates(visits).set_index("condition")
    flows = flow(visits).set_index("condition")
    rows = []
    for a, b in combinations(visits.conditions, 2):
        of_a, of_b = people[people["condition"] == a], people[people["condition"] == b]

        def values(frame: pd.DataFrame, column: str) -> list[float]:
            return [float(v) for v in frame[column].dropna()]

        counted = given_words(set(of_a["gave"]) | set(of_b["gave"]))
        continuous: list[tuple[str, str, Callable[[list[float], list[float]], Tested]]] = [
            ("advice", counted, lambda x, y: welch(x, y, alpha)),
            ("advice", "median decision time [s]", lambda x, y: welch(x, y, alpha, log=True)),
        ]
        columns = {counted: "advice", "median decision time [s]": "median_decision_s"}
        if visits.correct_action_recorded:
            continuous.insert(1, ("advice", "accuracy", lambda x, y: welch(x, y, alpha)))
            columns["accuracy"] = "accuracy"
        for family, measure, test in continuous:
            column = columns[measure]
            x, y = values(of_a, column), values(of_b, column)
            rows.append(_row(family, measure, a, b, test(x, y)))
        for column in [c for c in people.columns if c.startswith("scale_")]:
            tested = welch(values(of_a, column), values(of_b, column), alpha)
            rows.append(_row("scales", column.removeprefix("scale_"), a, b, tested))
        for key in answered.columns:
            x = [
                float(v)
                for v in answered.loc[answered.index.isin(of_a["session_id"]), key].dropna()
            ]
            y = [
                float(v)
                for v in answered.loc[answered.index.isin(of_b["session_id"]), key].dropna()
            ]
            rows.append(_row("items", key, a, b, mann_whitney(x, y, alpha)))
        for measure, got, of in (
            ("check passed at the first try", "first_try", "took"),
            ("check passed", "passed", "took"),
        ):
            tested = fisher(
                int(rates.loc[a, got]), int(rates.loc[a, of]),
                int(rates.loc[b, got]), int(rates.loc[b, of]), alpha,
            )  # fmt: skip
            rows.append(_row("rates", measure, a, b, tested))
        tested = fisher(
            int(flows.loc[a, "completed"]), int(flows.loc[a, "consented"]),
            int(flows.loc[b, "completed"]), int(flows.loc[b, "consented"]), alpha,
        )  # fmt: skip
        rows.append(_row("rates", "completed, of those who consented", a, b, tested))
    table = pd.DataFrame(
        rows, columns=[c for c in TEST_COLUMNS if c not in ("p_holm", "significant")]
    )
    table["p_holm"] = np.nan
    for _, group in table.groupby("family", sort=False):
        table.loc[group.index, "p_holm"] = holm(list(group["p"]))
    table["significant"] = [None if np.isnan(p) else bool(p < alpha) for p in table["p_holm"]]
    return table[TEST_COLUMNS]
