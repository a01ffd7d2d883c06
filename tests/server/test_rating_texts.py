"""The participant's texts for each kind of feedback: a task's induction, the check and the
questionnaire speak of rating moves under evaluative feedback and of advice otherwise; a
study's own texts still go over either default."""

from __future__ import annotations

from server.routes.pages import Visit, default_text
from study.schemas.visit import QuestionnaireSpec
from study.services.visit import rating_question
from tasks import get_task


def test_the_induction_has_texts_for_each_kind_per_task() -> None:
    for name in ("sorting", "gridworld"):
        task = get_task(name)
        for key in ("induction_1", "induction_3"):
            advice, rating = default_text(key, task), default_text(key, task, "evaluative")
            assert "**Good**" in rating and "**Good**" not in advice, (name, key)
        assert default_text("consent", task, "evaluative") == default_text("consent", task)
    assert "robot arm" in default_text("induction_1", get_task("sorting"), "evaluative")


def test_the_plan_and_the_time_rule_say_how_long_a_rating_may_take() -> None:
    visit = Visit("t", 1, 1, "running", 20, 0, {}, "color", feedback="evaluative",
                  rating_time_out_s=7.0)  # fmt: skip
    texts = visit.resolved_texts()
    assert "**you** rate each move: **Good** or **Bad**, within 7 seconds" in texts["induction_1"]
    assert "**7 seconds** for each rating" in texts["induction_3"]
    advised = Visit("t", 1, 1, "running", 20, 0, {}, "color").resolved_texts()
    assert "rate" not in advised["induction_1"] and "no time limit" in advised["induction_3"]
    own = Visit("t", 1, 1, "running", 20, 0, {"induction_1": "Ours."}, "color",
                feedback="evaluative").resolved_texts()  # fmt: skip
    assert own["induction_1"] == "Ours."


def test_the_check_and_the_questionnaire_speak_of_ratings() -> None:
    question = rating_question("agent")
    assert question.answer == "a" and "Good or Bad" in question.choices[0].label
    spec = QuestionnaireSpec()
    rated = spec.sections("agent", "evaluative")
    advised = spec.sections("agent")
    assert "the ratings you just gave" in rated[0].intro
    assert "the advice you just gave" in advised[0].intro
    assert rated[1].intro.endswith("the agent you rated?")
    assert advised[1].intro.endswith("the agent you advised?")
