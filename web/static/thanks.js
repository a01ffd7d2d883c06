// The thank-you page: the learner's collected reward per episode, live, until it finishes.
"use strict";
(() => {
  const config = JSON.parse(document.getElementById("page-config").textContent);
  const svg = document.getElementById("curve");
  const status = document.getElementById("learning-status");
  const ENDED = { finished: "Finished", stopped: "Stopped by the researcher", failed: "Stopped (error)" };

  async function refresh() {
    const response = await fetch("/api/participant/learning-curve", {
      headers: { Authorization: `Bearer ${config.token}` },
      cache: "no-store",
    });
    if (!response.ok) throw new Error(String(response.status));
    const data = await response.json();
    const points = data.curve.map((p) => [p.episode, p.collected_reward]);
    window.drawCurves(svg, [{ label: "the robot", points }], {
      xMax: data.episodes,
      empty: "The first round is under way…",
    });
    const done = data.curve.length;
    status.textContent = ENDED[data.status] || (data.queued
      ? "Queued: the robot waits for a free processor to practise"
      : data.status === "running"
      ? `Learning: round ${Math.min(done + 1, data.episodes)} of ${data.episodes}`
      : `Session ${data.status}`);
    status.dataset.mood = data.status === "running" ? "busy" : "done";
    return data.status !== "running" && data.status !== "paused";
  }

  async function loop() {
    for (;;) {
      let over = false;
      try {
        over = await refresh();
      } catch {
        status.textContent = "Connection lost. Trying again…";
      }
      if (over) return;
      await new Promise((resolve) => setTimeout(resolve, 2000));
    }
  }
  loop();
})();
