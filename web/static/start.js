// Induction step 3: start the participant's session, then go to the advice page.
"use strict";
(() => {
  const config = JSON.parse(document.getElementById("page-config").textContent);
  const button = document.getElementById("start");
  const error = document.getElementById("start-error");
  button.addEventListener("click", async () => {
    button.disabled = true;
    button.textContent = "Starting…";
    error.hidden = true;
    try {
      await window.participantStart(config.token);
    } catch (e) {
      error.textContent = `The session could not start (${e.message}). Please try again, or tell the researcher.`;
      error.hidden = false;
      button.disabled = false;
      button.textContent = "Start";
    }
  });
})();
