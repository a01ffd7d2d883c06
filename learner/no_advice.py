"""What an advisor answers when it has nothing to give, apart from the advisors so that
every advisor (the fitted ones' module included) can give it."""

from __future__ import annotations

import enum


class NoAdvice(enum.Enum):
    """What an advisor answers when it was asked and has nothing to give: a recorded stream
    that ran out. The strategy counts the request against its budget (the run asked, as
    the original did), and the learner takes its own action."""

    NO_ADVICE = "no advice"


NO_ADVICE = NoAdvice.NO_ADVICE
