// A recorded episode played back: the server reruns it once in a worker process, and this
// page steps through what came back (play, pause, step) on its own, telling the server
// which step it shows so the 3-D view draws it. Closing the page closes the playback.
"use strict";
(() => {
  const config = JSON.parse(document.getElementById("page-config").textContent);
  const $ = (id) => document.getElementById(id);
  const API = "/dashboard/api";
  const PLAY_EVERY_MS = 900;
  const KEEPALIVE_MS = 20000;
  let playback = null; // the server's PlaybackState once ready
  let current = 0;
  let timer = null;
  let keepalive = null;

  function showError(message) {
    $("playback-error").textContent = message;
    $("playback-error").hidden = !message;
  }

  const call = window.dashboardCall;


  async function loadEpisodes() {
    const episodes = await call(`${API}/sessions/${config.session}/episodes`);
    const select = $("episode");
    select.replaceChildren();
    if (!episodes.length) {
      select.append(new Option("No episode recorded yet", ""));
      return;
    }
    for (const e of episodes) {
      const advised = e.advised_steps ? `, ${e.advised_steps} advised` : "";
      const text = `${e.stage} episode ${e.episode}: ${e.steps} steps, reward ${e.collected_reward.toFixed(2)}${advised}`;
      const option = new Option(e.playable ? text : `${text} (no reset seed)`, `${e.stage}/${e.episode}`);
      option.disabled = !e.playable;
      select.append(option);
    }
  }

  // --- one step shown --------------------------------------------------------------
  function adviceAt(index) {
    return playback.advice.find((a) => a.index === index);
  }

  function seconds(s) {
    return s === null || s === undefined ? "—" : `${s.toFixed(2)} s`;
  }

  // Positions 0..n-1 are the steps' decisions; n is the episode's end (no action follows).
  function show(index, tellServer = true) {
    const steps = playback.steps;
    current = Math.max(0, Math.min(steps.length, index));
    const step = steps[current];
    const end = current === steps.length;
    $("step-number").textContent = end ? "end" : step.step;
    $("step-count").textContent = steps.length;
    $("step-global").textContent = end ? "—" : step.global_step;
    $("step-action").textContent = end ? "—" : step.action_name;
    $("step-action").dataset.action = end ? "" : step.action;
    $("step-source").textContent = end ? "—" : step.action_source;
    const reward = $("step-reward");
    reward.textContent = end ? "—" : step.reward.toFixed(2);
    reward.dataset.mood = end || step.reward === 0 ? "neutral" : step.reward > 0 ? "good" : "bad";
    const collected = steps.slice(0, current + 1).reduce((sum, s) => sum + s.reward, 0);
    $("step-collected").textContent = `${collected.toFixed(2)} of ${playback.collected_reward.toFixed(2)}`;
    $("step-image").src = end ? playback.end_image_url : step.image_url;
    $("scrub").value = current;
    const advice = adviceAt(current);
    $("step-advice").hidden = !advice;
    if (advice) {
      $("advice-number").textContent = `#${advice.advice_index + 1}`;
      $("advice-who").textContent = advice.advisor === "human" ? "the participant" : `the ${advice.advisor} advisor`;
      $("advice-action").textContent = advice.action_name;
      $("advice-time").textContent = advice.decision_time_s === null ? "" : `after ${seconds(advice.decision_time_s)}`;
    }
    for (const row of $("advice-list").children) row.classList.toggle("current", Number(row.dataset.index) === current);
    $("step-back").disabled = current === 0;
    $("step-forward").disabled = end;
    if (tellServer) {
      call(`${API}/playbacks/${playback.id}/show`, { method: "POST", body: JSON.stringify({ index: current }) }).catch((e) =>
        showError(`3-D view: ${e.message}`)
      );
    }
  }

  function adviceRows() {
    $("advice-turns").hidden = !playback.advice.length;
    $("advice-list").replaceChildren(
      ...playback.advice.map((a) => {
        const tr = document.createElement("tr");
        tr.dataset.advice = a.advice_index;
        tr.dataset.index = a.index;
        tr.innerHTML = `<td class="advice-index"></td><td class="advice-step"></td><td><img class="advice-image" width="48" height="48"></td><td class="advice-action"></td><td class="decision-time"></td>`;
        tr.querySelector(".advice-index").textContent = `#${a.advice_index + 1}`; // as the participant's page
        tr.querySelector(".advice-step").textContent = a.index + 1;
        const img = tr.querySelector(".advice-image");
        img.src = a.image_url;
        img.alt = `What the ${a.advisor} advisor saw at advice ${a.advice_index + 1}`;
        tr.querySelector(".advice-action").textContent = a.action_name;
        tr.querySelector(".decision-time").textContent = seconds(a.decision_time_s);
        tr.addEventListener("click", () => {
          pause();
          show(a.index);
        });
        return tr;
      })
    );
  }

  // --- play, pause, step ------------------------------------------------------------------
  function pause() {
    clearInterval(timer);
    timer = null;
    $("play").textContent = "Play";
    $("play").dataset.playing = "no";
  }

  function play() {
    if (current >= playback.steps.length) show(0);
    $("play").textContent = "Pause";
    $("play").dataset.playing = "yes";
    timer = setInterval(() => {
      if (current >= playback.steps.length) return pause();
      show(current + 1);
    }, PLAY_EVERY_MS);
  }

  $("play").addEventListener("click", () => (timer ? pause() : play()));
  $("step-forward").addEventListener("click", () => {
    pause();
    show(current + 1);
  });
  $("step-back").addEventListener("click", () => {
    pause();
    show(current - 1);
  });
  $("scrub").addEventListener("input", (event) => {
    pause();
    show(Number(event.target.value));
  });

  // --- opening and closing ----------------------------------------------------------------
  function closePlayback() {
    pause();
    clearInterval(keepalive);
    if (playback) {
      fetch(`${API}/playbacks/${playback.id}`, {
        method: "DELETE",
        keepalive: true,
        headers: { "X-Requested-With": "ideeprl-dashboard" },
      }).catch(() => {});
    }
    playback = null;
  }

  async function open(stage, episode) {
    closePlayback();
    $("player").hidden = true;
    $("playback-status").textContent = `Rerunning ${stage} episode ${episode}…`;
    const opened = await call(`${API}/sessions/${config.session}/episodes/${stage}/${episode}/playback`, { method: "POST" });
    let state = await call(opened.url);
    while (state.state === "rerunning") {
      await new Promise((resolve) => setTimeout(resolve, 300));
      state = await call(opened.url);
    }
    if (state.state === "failed") throw new Error(`the rerun failed: ${state.detail}`);
    playback = state;
    keepalive = setInterval(() => call(opened.url).catch((e) => showError(`Playback: ${e.message}`)), KEEPALIVE_MS);
    $("playback-status").textContent =
      `${stage} episode ${episode}: ${state.steps.length} steps, collected reward ${state.collected_reward.toFixed(2)}` +
      (state.detail ? `. Note: ${state.detail}` : "");
    $("scrub").max = state.steps.length;
    adviceRows();
    $("player").hidden = false;
    const scene = $("scene");
    scene.dataset.socket = `playback/${state.id}`;
    scene.src = window.sceneUrl(scene);
    show(0);
  }

  $("choose").addEventListener("submit", async (event) => {
    event.preventDefault();
    const [stage, episode] = $("episode").value.split("/");
    if (!stage) return;
    $("open").disabled = true;
    try {
      await open(stage, Number(episode));
      showError("");
    } catch (e) {
      $("playback-status").textContent = "";
      showError(`Playback: ${e.message}`);
    } finally {
      $("open").disabled = false;
    }
  });
  window.addEventListener("pagehide", closePlayback);

  loadEpisodes().catch((e) => showError(`Episodes: ${e.message}`));
})();
