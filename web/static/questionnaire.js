// The questionnaire after the advice: collect each item's answer (a slider counts only
// once moved), send them once, then go to the visit's end page.
"use strict";
(() => {
  const config = JSON.parse(document.getElementById("page-config").textContent);
  const form = document.getElementById("questionnaire-form");
  const error = document.getElementById("questionnaire-error");
  const submit = document.getElementById("submit");
  const items = [...form.querySelectorAll("fieldset.item")];

  for (const slider of form.querySelectorAll("input[type=range]")) {
    const shown = slider.parentElement.querySelector(".slider-value");
    const touch = () => {
      slider.dataset.touched = "true";
      slider.parentElement.classList.add("touched");
      shown.textContent = slider.value;
    };
    slider.addEventListener("input", touch);
    slider.addEventListener("change", touch);
    // A click, tap or key on the slider where it already stands (its midpoint, or an end
    // for Home/End) is an answer too, though the value does not change and no input event
    // comes: answered as a change, which also clears the item's "please answer".
    const answerAsItStands = () => {
      if (!slider.dataset.touched) slider.dispatchEvent(new Event("change", { bubbles: true }));
    };
    slider.addEventListener("pointerup", answerAsItStands);
    slider.addEventListener("keyup", (event) => {
      if (/^(Arrow|Home$|End$|Page)/.test(event.key)) answerAsItStands();
    });
  }

  // An answer given clears that item's "please answer".
  form.addEventListener("change", (event) => {
    const item = event.target.closest("fieldset.item");
    if (item) item.querySelector(".field-error").hidden = true;
    if (!form.querySelector(".field-error:not([hidden])")) error.hidden = true;
  });

  function answerOf(item) {
    const kind = item.dataset.kind;
    const prefer = item.querySelector("input[type=checkbox]:checked");
    if (prefer) return prefer.value;
    const range = item.querySelector("input[type=range]");
    if (range) return range.dataset.touched ? Number(range.value) : null;
    const checked = item.querySelector("input[type=radio]:checked");
    if (kind === "likert") return checked ? Number(checked.value) : null;
    if (kind === "choice") return checked ? checked.value : null;
    const field = item.querySelector("input.field");
    const text = field.value.trim();
    if (!text) return null;
    return kind === "number" ? Number(text) : text;
  }

  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    error.hidden = true;
    const answers = {};
    const missing = [];
    for (const item of items) {
      const value = answerOf(item);
      item.querySelector(".field-error").hidden = true;
      if (value === null && "required" in item.dataset) missing.push(item);
      if (value === null) continue;
      (answers[item.dataset.instrument] ??= {})[item.dataset.item] = value;
    }
    if (missing.length) {
      for (const item of missing) item.querySelector(".field-error").hidden = false;
      error.textContent = `Please answer the ${missing.length} question${missing.length === 1 ? "" : "s"} marked in red.`;
      error.hidden = false;
      missing[0].scrollIntoView({ block: "center" });
      return;
    }
    submit.disabled = true;
    submit.textContent = "Sending…";
    try {
      await window.participantCall(config.token, "/api/participant/questionnaire", {
        method: "POST",
        body: JSON.stringify({ answers }),
      });
      window.location.assign(`/p/${config.token}/end`);
    } catch (e) {
      if (e.status === 409) {  // sent already (another tab): the visit is over
        window.location.assign(`/p/${config.token}/end`);
        return;
      }
      error.textContent = `Your answers could not be sent (${e.message}). Please try again.`;
      error.hidden = false;
      submit.disabled = false;
      submit.textContent = "Send my answers";
    }
  });
})();
