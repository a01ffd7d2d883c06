"""A small online study's visits written out by hand, for the human section's tests."""

from __future__ import annotations

import pandas as pd

from analysis.human import Visits

T = "2026-12-06T10:00:00Z"


def hand_visits() -> Visits:
    """Two conditions. `early`: sessions 1, 2, 3 completed, 4 excluded, 5 declined; `late`:
    sessions 6, 7 completed, 8 timed out, 9 still under way."""
    sessions = pd.DataFrame(
        [
            (1, "early", "completed", T), (2, "early", "completed", T),
            (3, "early", "completed", T), (4, "early", "excluded", T),
            (5, "early", "declined", None), (6, "late", "completed", T),
            (7, "late", "completed", T), (8, "late", "timed_out", T), (9, "late", None, T),
            (10, None, None, None),  # a batch run beside the study: no visit
        ],
        columns=["session_id", "condition", "outcome", "consented_at"],
    )  # fmt: skip
    advice = pd.DataFrame(
        [
            # early: 1 gives 3 advice (2 right), 2 gives 2 (2 right), 3 gives 1 (0 right)
            (1, "human", 0, 1.0, 0), (1, "human", 1, 2.0, 1), (1, "human", 2, 4.0, 3),
            (2, "human", 3, 2.0, 3), (2, "human", 3, 2.0, 3),
            (3, "human", 1, 8.0, 2), (3, "human", None, None, 2),  # asked, none given
            # late: 6 gives 2 (1 right), 7 gives 2 (2 right)
            (6, "human", 0, 1.0, 0), (6, "human", 0, 3.0, 1),
            (7, "human", 2, 0.5, 2), (7, "human", 2, 1.5, 2),
        ],
        columns=["session_id", "advisor", "action", "decision_time_s", "correct_action"],
    )  # fmt: skip
    check = pd.DataFrame(
        [
            # early: 1 right at once, 2 at the second try, 3 at once, 4 wrong twice
            (1, 1, "q1", True), (1, 1, "q2", True),
            (2, 1, "q1", True), (2, 1, "q2", False), (2, 2, "q1", True), (2, 2, "q2", True),
            (3, 1, "q1", True), (3, 1, "q2", True),
            (4, 1, "q1", False), (4, 1, "q2", True), (4, 2, "q1", False), (4, 2, "q2", True),
            # late: 6, 7 right at once, 8 at the second try
            (6, 1, "q1", True), (6, 1, "q2", True), (7, 1, "q1", True), (7, 1, "q2", True),
            (8, 1, "q1", False), (8, 1, "q2", True), (8, 2, "q1", True), (8, 2, "q2", True),
        ],
        columns=["session_id", "attempt", "question", "correct"],
    )  # fmt: skip
    questionnaire = pd.DataFrame(
        [
            (1, "nasa_tlx", "mental", 50.0), (2, "nasa_tlx", "mental", 70.0),
            (3, "nasa_tlx", "mental", 60.0), (6, "nasa_tlx", "mental", 20.0),
            (7, "nasa_tlx", "mental", 30.0),
            (1, "custom", "fun", 4.0), (2, "custom", "fun", 4.0), (3, "custom", "fun", 4.0),
            (6, "custom", "fun", 4.0), (7, "custom", "fun", 4.0),
            (1, "demographics", "age", None),
        ],
        columns=["session_id", "instrument", "item", "value_number"],
    )  # fmt: skip
    scales = pd.DataFrame(
        [(1, "trust", 5.0), (2, "trust", 6.0), (3, "trust", 4.0), (6, "trust", 3.0),
         (7, "trust", 2.0)],
        columns=["session_id", "scale", "score"],
    )  # fmt: skip
    return Visits(sessions, advice, check, questionnaire, scales)


def rated_visits(correct_action: bool = True) -> Visits:
    """`hand_visits` with `late`'s participants rating instead of advising: their turns
    are in the feedback table (`correct_action` recorded beside each rating, or not)."""
    visits = hand_visits()
    feedback = pd.DataFrame(
        [
            # 6: good of the correct action (right), good of another (wrong), bad of another
            # (right), no answer: 3 given, accuracy 2/3, median 3.0 s
            (6, "human", 0, 1.0, 1.0, 0), (6, "human", 1, 1.0, 3.0, 2),
            (6, "human", 2, -1.0, 5.0, 0), (6, "human", 3, None, None, 3),
            # 7: bad of the correct action (wrong), 0 (neither: given, not scored): 2 given,
            # accuracy 0/1, median 1.0 s
            (7, "human", 2, -1.0, 0.5, 2), (7, "human", 1, 0.0, 1.5, 1),
        ],
        columns=["session_id", "evaluator", "action", "judgement", "decision_time_s",
                 "correct_action"],
    )  # fmt: skip
    if not correct_action:
        feedback = feedback.drop(columns="correct_action")
    advice = visits.advice[~visits.advice["session_id"].isin([6, 7])]
    return Visits(
        visits.sessions, advice, visits.check, visits.questionnaire, visits.scales, feedback
    )
