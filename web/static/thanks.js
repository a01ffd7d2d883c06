// The thank-you page: where the robot is in the queue for a training slot (place and an
// estimate), then the points it collects per round, live, until it finishes. One state
// at a time: never an empty plot, never two labels that disagree.
"use strict";
(() => {
  const config = JSON.parse(document.getElementById("page-config").textContent);
  const $ = (id) => document.getElementById(id);
  const ENDED = { finished: "Finished", stopped: "Stopped by the researcher", failed: "Stopped (a technical problem)" };
  const ORDINAL = ["", "next", "second", "third"];
  const AGENT = config.agent || "robot"; // what the page calls the learner

  function inWords(seconds) {
    if (seconds === null || seconds === undefined) return null;
    if (seconds < 60) return "in less than a minute";
    const minutes = Math.round(seconds / 60);
    if (minutes < 90) return `in about ${minutes} minute${minutes === 1 ? "" : "s"}`;
    return `in about ${Math.round(minutes / 60)} hours`;
  }

  function showQueue(data) {
    const place = data.queue_place;
    $("queue").hidden = false;
    $("queue").dataset.place = place ?? "";
    $("queue-place-text").textContent = place
      ? `Your ${AGENT} is number ${place} in line${place <= 3 ? ` (${ORDINAL[place]} to start)` : ""}: other ${AGENT}s are practising first.`
      : `Your ${AGENT} is waiting for its turn to practise.`;
    const when = inWords(data.wait_s);
    $("queue-wait").textContent = when
      ? `It should start practising ${when}. You may close this window at any time.`
      : `We will show how long it should take once ${/^[aeiou]/i.test(AGENT) ? "an" : "a"} ${AGENT} ahead of it has finished a round. You may close this window at any time.`;
  }

  async function refresh() {
    const response = await fetch("/api/participant/learning-curve", {
      headers: { Authorization: `Bearer ${config.token}` },
      cache: "no-store",
    });
    if (!response.ok) throw new Error(String(response.status));
    const data = await response.json();
    const points = data.curve.map((p) => [p.episode, p.collected_reward]);
    const queued = data.status === "queued"; // waiting for a trainer slot, as the researcher sees it
    $("queue").hidden = !queued;
    if (queued) showQueue(data);
    const plotted = !queued && points.length > 0;
    $("curve").toggleAttribute("hidden", !plotted); // an <svg> has no `hidden` property
    $("curve-caption").hidden = !plotted;
    if (plotted) {
      window.drawCurves($("curve"), [{ label: `the ${AGENT}`, points }], {
        xMax: data.episodes,
        xLabel: "round",
        yLabel: "points",
      });
    }
    const waiting = !queued && !points.length;
    $("curve-waiting").hidden = !waiting;
    if (waiting) {
      $("curve-waiting").textContent = ENDED[data.status]
        ? `The ${AGENT} did not finish a round.`
        : `The ${AGENT} has started practising. The points of its first round appear here when it ends.`;
    }
    const status = $("learning-status");
    status.textContent = ENDED[data.status] || (queued
      ? `Waiting in line${data.queue_place ? `: number ${data.queue_place}` : ""}`
      : data.status === "running"
      ? `Practising: round ${Math.min(points.length + 1, data.episodes)} of ${data.episodes}`
      : data.status === "paused" ? "Paused by the researcher" : "Not practising now");
    const going = ["queued", "running"].includes(data.status);
    status.dataset.mood = going ? "busy" : "done";
    return !going && data.status !== "paused";
  }

  async function loop() {
    for (;;) {
      let over = false;
      try {
        over = await refresh();
      } catch {
        $("learning-status").textContent = "Connection lost. Trying again…";
      }
      if (over) return;
      await new Promise((resolve) => setTimeout(resolve, 2000));
    }
  }
  loop();
})();
