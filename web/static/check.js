// The comprehension check: send one try; a pass starts the session and opens the advice
// page, a wrong try says which questions to read again, the last wrong try ends the visit.
"use strict";
(() => {
  const config = JSON.parse(document.getElementById("page-config").textContent);
  const form = document.getElementById("check-form");
  const error = document.getElementById("check-error");

  function fail(message, button, label) {
    error.textContent = message;
    error.hidden = false;
    button.disabled = false;
    button.textContent = label;
  }

  async function start(button) {
    button.disabled = true;
    button.textContent = "Starting…";
    await window.participantStart(config.token);
  }

  function answers() {
    const chosen = {};
    for (const set of form.querySelectorAll("fieldset[data-question]")) {
      const picked = set.querySelector("input:checked");
      if (picked) chosen[set.dataset.question] = picked.value;
    }
    return chosen;
  }

  const startButton = document.getElementById("start");
  if (startButton) {
    startButton.addEventListener("click", () =>
      start(startButton).catch((e) => fail(`The session could not start (${e.message}). Please try again.`, startButton, "Start")),
    );
    return;
  }

  const submit = document.getElementById("submit");
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    error.hidden = true;
    const chosen = answers();
    const sets = [...form.querySelectorAll("fieldset[data-question]")];
    const missing = sets.filter((set) => !(set.dataset.question in chosen));
    for (const set of sets) set.querySelector(".field-error").hidden = true;
    if (missing.length) {
      fail("Please answer every question.", submit, "Check my answers");
      missing[0].scrollIntoView({ block: "center" });
      return;
    }
    submit.disabled = true;
    submit.textContent = "Checking…";
    try {
      const result = await window.participantCall(config.token, "/api/participant/check", {
        method: "POST",
        body: JSON.stringify({ answers: chosen }),
      });
      if (result.excluded) {
        window.location.assign(`/p/${config.token}/end`);
      } else if (result.correct) {
        await start(submit);
      } else {
        for (const set of sets) set.querySelector(".field-error").hidden = !result.wrong.includes(set.dataset.question);
        const left = result.tries - result.tries_used;
        document.getElementById("tries-left").textContent = left;
        document.getElementById("tries-word").textContent = left === 1 ? "try" : "tries";
        fail(`Some answers are not right. You have ${left} ${left === 1 ? "try" : "tries"} left.`, submit, "Check my answers");
      }
    } catch (e) {
      fail(`Your answers could not be sent (${e.message}). Please try again.`, submit, "Check my answers");
    }
  });
})();
