// The comprehension check: send one try; a pass starts the session and opens the advice
// page, a wrong try says which questions to read again, the last wrong try ends the visit.
"use strict";
(() => {
  const config = JSON.parse(document.getElementById("page-config").textContent);
  const form = document.getElementById("check-form");
  const error = document.getElementById("check-error");
  const auth = { Authorization: `Bearer ${config.token}` };

  async function detail(response) {
    const body = await response.json().catch(() => ({}));
    if (typeof body.detail === "string") return body.detail;
    if (Array.isArray(body.detail) && body.detail.length) return body.detail[0].msg;
    return `error ${response.status}`;
  }

  function fail(message, button, label) {
    error.textContent = message;
    error.hidden = false;
    button.disabled = false;
    button.textContent = label;
  }

  async function start(button) {
    button.disabled = true;
    button.textContent = "Starting…";
    const response = await fetch("/api/participant/start", { method: "POST", headers: auth });
    if (!response.ok) throw new Error(await detail(response));
    window.location.assign(`/p/${config.token}/advise`);
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
      const response = await fetch("/api/participant/check", {
        method: "POST",
        headers: { ...auth, "Content-Type": "application/json" },
        body: JSON.stringify({ answers: chosen }),
      });
      if (!response.ok) throw new Error(await detail(response));
      const result = await response.json();
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
