// The advice page: follows the session's state by long-polling, enables the action
// buttons when the robot waits for advice and the 3-D view has finished showing its last
// move, and sends one advice per click or key press. After the last it follows on until
// that choice's result is shown (or the last move's time is up), then moves on. Under
// evaluative feedback a turn shows the move the learner made and asks for a rating instead:
// Good or Bad (click, touch, Y or N), within the run's time-out, counted down on the page.
"use strict";
(() => {
  const config = JSON.parse(document.getElementById("page-config").textContent);
  const $ = (id) => document.getElementById(id);
  const buttons = [...document.querySelectorAll("button.action:not(.rate)")];
  const rates = [...document.querySelectorAll("button.rate")];
  const RATING = config.feedback === "evaluative"; // turns ask for ratings, not advice
  const RATE_KEYS = { y: "good", "+": "good", n: "bad", "-": "bad" };
  // the sorting robot's keys; another task's come with the page
  const KEYS = config.keys || { g: 0, r: 1, arrowright: 1, l: 2, arrowleft: 2, d: 3, 1: 0, 2: 1, 3: 2, 4: 3 };
  const LIVE = config.liveView !== false; // the task has a live 3-D view, else frames
  const SORTING = config.sorting !== false; // the sorting robot's words for its arm and rewards
  const AGENT = config.agent || "robot"; // what the page calls the learner
  const LAST_MOVE_MS = 4000;
  const FIRST_VIEW_WAIT_MS = 2000; // the longest a turn waits for the 3-D view's first frame
  const VIEW_POLL_MS = 100; // how often a turn waiting for that frame asks for it
  const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
  const capital = (name) => name.charAt(0).toUpperCase() + name.slice(1); // as on the buttons

  let version = null;
  let enabledFor = null; // the advice index the buttons answer, or null
  let generation = 0; // bumps on every state, so stale waits give up
  let finished = false; // the last choice is made: the page waits for its result, then goes on
  let leaving = false;
  let latest = null; // the latest state shown
  let sentIndex = null;
  let activeSince = null; // performance.now() when the buttons became active
  let readinessPolling = false;
  let beforeFirstTurn = false; // the latest state: no advice asked yet, robot practising
  let idleWarning = null; // the timer of an online study's warning before its idle limit
  let sceneShown = !LIVE; // the 3-D view has drawn the robot's scene (no view: nothing to wait for)

  function api(path, options = {}) {
    const headers = { Authorization: `Bearer ${config.token}` };
    if (options.body) headers["Content-Type"] = "application/json";
    return fetch(path, { ...options, headers, cache: "no-store" });
  }

  function setStatus(text, mood) {
    $("status-text").textContent = text;
    $("status").dataset.mood = mood;
  }

  function setButtons(on) {
    for (const b of RATING ? rates : buttons) {
      b.disabled = !on;
      // a new turn shows no choice made yet: the last one's green mark (kept 900 ms) would
      // read as a button already chosen when the turn comes sooner
      if (on) b.classList.remove("chosen");
    }
    document.body.classList.toggle("your-turn", on);
    clearTimeout(idleWarning);
    if (on && config.idleLimitS) idleWarning = setTimeout(warnIdle, warnAfterS(config.idleLimitS) * 1000);
  }

  // An online study ends a visit that leaves a turn unanswered for its idle limit (counted
  // by the robot from when it asked, a little before the buttons light up): a warning well
  // before, with the time left, instead of an end without notice.
  const warnAfterS = (limit) => Math.max(limit / 2, limit - 90);
  function warnIdle() {
    const left = config.idleLimitS - warnAfterS(config.idleLimitS);
    const when = left >= 120 ? `${Math.round(left / 60)} minutes` : `${Math.round(left)} seconds`;
    setStatus(`Are you still there? Please choose within about ${when}, or the study ends.`, "paused");
  }

  function rewardWords(reward) {
    if (reward === null || reward === undefined) return ["—", "", ""];
    const shown = (reward > 0 ? "+" : "") + String(Math.round(reward * 100) / 100);
    if (!SORTING) return [shown, reward > 0 ? "points gained" : reward < 0 ? "points lost" : "no points this time", reward > 0 ? "good" : reward < 0 ? "bad" : "neutral"];
    if (reward >= 0.99) return [shown, "all objects sorted: round complete!", "good"];
    if (reward > 0) return [shown, "correct placement", "good"];
    if (reward <= -0.99) return [shown, "wrong table: the objects are laid out again", "bad"];
    if (reward < 0) return [shown, "a small cost: the round is getting long", "neutral"];
    return [shown, "no points this time", "neutral"];
  }

  function showCounter(s) {
    $("advice-left").textContent = s.advice_left;
    $("advice-budget").textContent = s.advice_budget;
    const done = s.advice_budget ? (100 * s.advice_given) / s.advice_budget : 100;
    $("meter-fill").style.width = `${done.toFixed(1)}%`;
  }

  function showReward(s) {
    const [shown, words, mood] = rewardWords(s.last_reward);
    $("last-reward").textContent = shown;
    $("last-reward").dataset.mood = mood;
    $("last-reward-text").textContent = s.last_reward === null ? "No choice yet." : words;
  }

  function showHistory(s) {
    const list = $("history");
    list.replaceChildren();
    const items = [...s.history].reverse();
    if (!items.length) {
      const li = document.createElement("li");
      li.className = "muted";
      li.textContent = "None yet.";
      list.append(li);
    }
    for (const item of items) {
      const li = document.createElement("li");
      const [shown, , mood] = rewardWords(item.reward);
      li.innerHTML = `<span class="history-index"></span><span class="history-action"></span><span class="reward small"></span>`;
      li.children[0].textContent = `#${item.advice_index + 1}`;
      li.children[1].textContent = capital(item.action_name);
      li.children[2].textContent = item.reward === null ? "…" : shown;
      li.children[2].dataset.mood = mood;
      list.append(li);
    }
  }

  function showObservation(s) {
    if (s.frame_png && $("frame")) {
      $("frame").src = `data:image/png;base64,${s.frame_png}`;
      $("frame").hidden = false;
      $("frame-empty").hidden = true;
    }
    if (!s.observation_png) return;
    $("observation").src = `data:image/png;base64,${s.observation_png}`;
    $("observation").hidden = false;
    $("observation-empty").hidden = true;
  }

  // An alternating strategy's turn comes after moves the robot chose itself: say so, or
  // the scene seems to have changed by more than the participant's last choice.
  function ownMovesWords(n) {
    if (!n) return "";
    return ` Since your last choice it moved ${n === 1 ? "once" : `${n} times`} on its own.`;
  }

  // The sentence, and beside the camera image a small map of the three tables with the
  // arm's one lit: the image alone can make a side table look like the center one.
  function showArm(s, on) {
    if (!SORTING) {  // the arm's words and map are the sorting robot's
      $("holding").hidden = !on || !s.own_moves;
      $("arm-words").textContent = "";
      $("own-moves").textContent = on ? ownMovesWords(s.own_moves).trim() : "";
      $("own-moves").hidden = !$("own-moves").textContent;
      return;
    }
    $("holding").hidden = !on;
    $("arm-words").textContent = on ? window.describeArm(s) : "";
    $("own-moves").textContent = on ? ownMovesWords(s.own_moves) : "";
    $("own-moves").hidden = !$("own-moves").textContent;
    $("holding").dataset.held = on && s.held ? "yes" : "no";
    const map = $("station-map");
    map.hidden = !on || !s.station;
    map.dataset.station = on && s.station ? s.station : "";
    map.setAttribute("aria-label", on && s.station ? `The arm is ${window.describeStation(s.station)}` : "");
  }

  async function waitForPlayback(gen) {
    for (let i = 0; i < 600 && gen === generation; i++) {
      const response = await api("/api/participant/playback").catch(() => null);
      if (!response || !response.ok) return;
      const { remaining_s: left, scene_shown: shown } = await response.json();
      if (shown === true) sceneShown = true;
      if (left <= 0) return;
      await sleep(Math.min(1000, left * 1000 + 20));
    }
  }

  // Until the 3-D view has drawn its first frame (viser's client loading, software WebGL
  // starting) its panel is blank: the page says so until it has.
  async function watchView() {
    $("scene-loading").hidden = false;
    while (!sceneShown && !leaving) {
      const response = await api("/api/participant/playback").catch(() => null);
      if (response && response.ok) sceneShown = (await response.json()).scene_shown === true;
      if (!sceneShown) await sleep(500);
    }
    $("scene-loading").hidden = true;
  }

  // A turn waits a moment for that first frame, never long: the camera image and the
  // sentence say where the robot is meanwhile. It asks the server itself every
  // VIEW_POLL_MS: `watchView`'s slower polls would keep the buttons off up to 500 ms
  // after the view has drawn.
  async function waitForView(gen) {
    const until = performance.now() + FIRST_VIEW_WAIT_MS;
    while (!sceneShown && gen === generation && performance.now() < until) {
      const response = await api("/api/participant/playback").catch(() => null);
      if (response && response.ok && (await response.json()).scene_shown === true) sceneShown = true;
      if (!sceneShown) await sleep(VIEW_POLL_MS);
    }
  }

  const VISIT_ENDED = ["declined", "excluded", "timed_out"];
  async function render(s) {
    if (finished && !s.history.length) return; // the session is over: keep what is shown
    latest = s;
    showCounter(s);
    showReward(s);
    showHistory(s);
    if (finished) return; // the last choice's result, which `finish` waits for
    const gen = ++generation;
    // Advice over: every turn given, or the learner already waits in line to practise
    // (the thank-you page shows its place).
    if ((s.advice_budget > 0 && s.advice_left === 0) || s.status === "queued") return finish(gen);
    const ready =
      s.status === "running" && s.advice_wanted && !s.robot_moving && s.advice_index !== sentIndex;
    if (!ready) {
      if (RATING && enabledFor !== null && sentIndex !== enabledFor && s.status === "running") noAnswer();
      enabledFor = null;
      beforeFirstTurn = false;
      setButtons(false);
      showArm(s, false);
      if (VISIT_ENDED.includes(s.status)) return window.location.assign(`/p/${config.token}`); // its end page
      if (s.status !== "running") setStatus(s.message || `The session is ${s.status}.`, "paused");
      else if (s.robot_moving || sentIndex !== null) setStatus(`The ${AGENT} is moving…`, "busy");
      else if (s.advice_given === 0) showReadiness();
      else setStatus(`The ${AGENT} is exploring on its own. Your first turn comes in a moment…`, "busy");
      return;
    }
    hideReadiness();
    if (enabledFor === s.advice_index) return;
    setButtons(false);
    if (RATING) return askRating(s, gen);
    setStatus(`The ${AGENT} is moving…`, "busy");
    await waitForPlayback(gen);
    if (!sceneShown) {
      setStatus("The 3-D view is loading…", "busy");
      await waitForView(gen);
    }
    if (gen !== generation) return;
    showObservation(s);
    showArm(s, true);
    enabledFor = s.advice_index;
    sentIndex = null;
    // a new turn: the last choice's line ("✓ Sent: Move left") would read as this turn's
    $("feedback").textContent = "";
    delete $("feedback").dataset.mood;
    setButtons(true);
    activeSince = performance.now();
    setStatus(`Your turn: what should the ${AGENT} do?`, "turn");
  }

  // A rating turn: the move is shown (the 3-D view replays it; a task's frame shows where it
  // led), then Good and Bad light up until the learner's time-out, counted from when it
  // asked (the state says how much of it was left when it was read).
  let clock = null;
  async function askRating(s, gen) {
    const deadline = s.receivedAt + 1000 * (s.rating_left_s ?? config.ratingTimeOutS);
    setStatus(`The ${AGENT} is moving…`, "busy");
    await waitForPlayback(gen);
    if (gen !== generation) return;
    showObservation(s);
    showArm(s, false);
    const name = capital(config.actionNames[s.rated_action]);
    $("rating-question").textContent = `The ${AGENT} chose “${name}”${rewardNote(s.rated_reward)}. Was that a good choice?`;
    if (enabledFor !== null && sentIndex !== enabledFor) noAnswer(); // the last turn lapsed
    enabledFor = s.advice_index;
    sentIndex = null;
    $("rating").dataset.turn = String(s.advice_index);
    $("feedback").textContent = lapsed ? `No answer to the last move: the ${AGENT} went on.` : "";
    delete $("feedback").dataset.mood;
    lapsed = false;
    setButtons(true);
    activeSince = performance.now();
    setStatus(`Your turn: rate the ${AGENT}'s move`, "turn");
    clearInterval(clock);
    const tick = () => {
      const left = Math.max(0, deadline - performance.now());
      const total = 1000 * config.ratingTimeOutS;
      $("rating-clock").style.width = `${((100 * left) / total).toFixed(1)}%`;
      $("rating-left").textContent = `${Math.ceil(left / 1000)} s left to rate`;
      if (left > 0 && enabledFor === s.advice_index) return;
      clearInterval(clock);
      $("rating-clock").style.width = "0%";
      $("rating-left").textContent = "";
      if (enabledFor !== s.advice_index) return;
      noAnswer();
      enabledFor = null;
      setButtons(false);
    };
    clock = setInterval(tick, 100);
    tick();
  }

  // A rating turn closed without an answer (its time-out): said until the next turn's.
  let lapsed = false;
  function noAnswer() {
    lapsed = true;
    clearInterval(clock);
    $("rating-clock").style.width = "0%";
    $("rating-left").textContent = "";
    $("feedback").textContent = `No answer: the ${AGENT} goes on.`;
    delete $("feedback").dataset.mood;
    setStatus(`The ${AGENT} is moving…`, "busy");
  }

  function rewardNote(reward) {
    if (reward === null || reward === undefined) return "";
    const [shown, words] = rewardWords(reward);
    return ` (${shown}: ${words})`;
  }

  async function rate(rating) {
    if (enabledFor === null) return;
    // the decision time: from Good and Bad lighting up to this click, touch or key
    const decision = activeSince === null ? null : (performance.now() - activeSince) / 1000;
    activeSince = null;
    const index = enabledFor;
    enabledFor = null;
    sentIndex = index;
    setButtons(false);
    const button = rates.find((b) => b.dataset.rating === rating);
    button.classList.add("chosen");
    setTimeout(() => button.classList.remove("chosen"), 900);
    const word = capital(rating);
    $("feedback").textContent = `Sending “${word}”…`;
    for (let attempt = 0; attempt < 5; attempt++) {
      let response;
      try {
        response = await api("/api/participant/rating", {
          method: "POST",
          body: JSON.stringify({ advice_index: index, rating, decision_time_s: decision }),
        });
      } catch {
        await sleep(1000 * (attempt + 1));
        continue; // the same rating again is stored once
      }
      if (response.ok) {
        $("feedback").textContent = `✓ Rated: ${word}`;
        $("feedback").dataset.mood = "good";
        setStatus(`The ${AGENT} is moving…`, "busy");
        return;
      }
      const body = await response.json().catch(() => ({}));
      $("feedback").textContent = typeof body.detail === "string" ? body.detail : `Not sent (error ${response.status}).`;
      $("feedback").dataset.mood = "bad";
      version = null;
      return;
    }
    $("feedback").textContent = "Not sent: the connection is lost.";
    $("feedback").dataset.mood = "bad";
    version = null;
  }

  async function finish(gen) {
    if (finished) return;
    finished = true;
    enabledFor = null;
    setButtons(false);
    setStatus("That was your last choice. Thank you!", "turn");
    showArm({}, false);
    // Show the last advised move (the view shows the robot's own moves without motion)
    // and what it earned, which comes once the robot has made it; never wait long.
    const until = performance.now() + LAST_MOVE_MS;
    await Promise.race([waitForPlayback(gen), sleep(LAST_MOVE_MS)]);
    while (!lastResultShown() && performance.now() < until) await sleep(100);
    await sleep(800);
    leaving = true;
    window.location.assign(`/p/${config.token}`);  // thanks, or an online study's questionnaire
  }

  function lastResultShown() {
    const last = latest && latest.history[latest.history.length - 1];
    return Boolean(last) && last.reward !== null;
  }

  // Before the first turn the robot practises with random moves; show how far it is.
  async function showReadiness() {
    beforeFirstTurn = true;
    if (readinessPolling) return;
    readinessPolling = true;
    try {
      while (beforeFirstTurn && !finished) {
        const response = await api("/api/participant/readiness").catch(() => null);
        if (!response || !response.ok) break;
        const r = await response.json();
        if (r.ready || !beforeFirstTurn) break;
        const total = Math.max(1, r.steps_before_first_turn);
        const done = Math.min(r.steps_done, total);
        setStatus(`Getting the ${AGENT} ready: ${done} of ${total} practice moves done. Your first turn comes next.`, "busy");
        $("scene-wait").hidden = false;
        $("scene-wait-fill").style.width = `${((100 * done) / total).toFixed(1)}%`;
        $("scene-wait-text").textContent = `The ${AGENT} practises on its own: ${done} of ${total} moves`;
        await sleep(500);
      }
    } finally {
      readinessPolling = false;
    }
    if (beforeFirstTurn && !finished) {
      setStatus(`The ${AGENT} is getting ready. Your first turn comes in a moment…`, "busy");
    }
    $("scene-wait").hidden = true;
  }

  function hideReadiness() {
    beforeFirstTurn = false;
    $("scene-wait").hidden = true;
  }

  async function send(action) {
    if (enabledFor === null) return;
    // The participant's decision time: from the buttons becoming active to this click or
    // key, on the browser's monotonic clock (the server's time also counts the replay).
    const decision = activeSince === null ? null : (performance.now() - activeSince) / 1000;
    activeSince = null;
    const index = enabledFor;
    enabledFor = null;
    sentIndex = index;
    setButtons(false);
    const button = buttons.find((b) => Number(b.dataset.action) === action);
    button.classList.add("chosen");
    setTimeout(() => button.classList.remove("chosen"), 900);
    const name = capital(config.actionNames[action]);
    $("feedback").textContent = `Sending “${name}”…`;
    setStatus(`The ${AGENT} is moving…`, "busy");
    for (let attempt = 0; attempt < 5; attempt++) {
      let response;
      try {
        response = await api("/api/participant/advice", {
          method: "POST",
          body: JSON.stringify({ advice_index: index, action, decision_time_s: decision }),
        });
      } catch {
        await sleep(1000 * (attempt + 1));
        continue; // the same advice again is stored once
      }
      if (response.ok) {
        $("feedback").textContent = `✓ Sent: ${name}`;
        $("feedback").dataset.mood = "good";
        return;
      }
      const body = await response.json().catch(() => ({}));
      $("feedback").textContent = typeof body.detail === "string" ? body.detail : `Not sent (error ${response.status}).`;
      $("feedback").dataset.mood = "bad";
      sentIndex = null;
      version = null; // fetch the state afresh
      return;
    }
    $("feedback").textContent = "Not sent: the connection is lost. Please try again.";
    $("feedback").dataset.mood = "bad";
    sentIndex = null;
    version = null;
  }

  async function follow() {
    let failures = 0;
    while (!leaving) {
      const path = version === null ? "/api/participant/state" : `/api/participant/state?after=${version}&timeout=20`;
      try {
        const response = await api(path);
        if (response.status === 401 || response.status === 403) {
          setStatus("This link is not valid any more. Please contact the researcher.", "paused");
          setButtons(false);
          return;
        }
        if (!response.ok) throw new Error(String(response.status));
        const s = await response.json();
        s.receivedAt = performance.now();
        failures = 0;
        version = s.version;
        render(s);
      } catch {
        failures += 1;
        setButtons(false);
        enabledFor = null;
        if (!finished) setStatus("Connection lost. Trying again…", "paused");
        await sleep(Math.min(10000, 1000 * failures));
        version = null;
      }
    }
  }

  for (const b of buttons) b.addEventListener("click", () => send(Number(b.dataset.action)));
  for (const b of rates) b.addEventListener("click", () => rate(b.dataset.rating));
  document.addEventListener("keydown", (event) => {
    if (event.ctrlKey || event.metaKey || event.altKey) return;
    if (RATING) {
      const rating = RATE_KEYS[event.key.toLowerCase()];
      if (rating === undefined) return;
      event.preventDefault();
      return rate(rating);
    }
    const action = KEYS[event.key.toLowerCase()];
    if (action === undefined) return;
    event.preventDefault();
    send(action);
  });
  if (LIVE) {
    const scene = $("scene");
    scene.src = window.sceneUrl(scene);
    window.keepKeysOnPage(scene);
    watchView();
  }
  follow();
})();
