// The researchers' dashboard: polls the overview and the learning curves, and sends
// start/pause/resume/stop, new studies and new participant sessions; builds and shows a
// study's report (the paper's analysis).
"use strict";
(() => {
  const COLORS = ["#2f6f8f", "#c8572d", "#2e7d4f", "#7a4fb3", "#a0711b", "#b3412e", "#3d8f8a", "#8f2f6f"];
  // Past the palette, hues a golden angle apart: every session's curve its own colour.
  const colorOf = (i) =>
    i < COLORS.length ? COLORS[i] : `hsl(${((i * 137.508) % 360).toFixed(1)}, 60%, ${i % 2 ? 34 : 46}%)`;
  const COMMANDS = {
    created: ["start", "stop"],
    running: ["pause", "stop"],
    queued: ["pause", "stop"], // running, its advice over, waiting for a trainer slot
    paused: ["resume", "stop"],
    stopped: ["resume"],
    interrupted: ["resume", "stop"],
    abandoned: ["resume", "stop"],
  }; // declined, excluded, timed_out, finished: over
  const COUNTS = ["target", "completed", "in_progress", "declined", "excluded", "timed_out"];
  const $ = (id) => document.getElementById(id);
  const template = $("study-template");
  const sections = new Map();

  function showError(message) {
    $("dashboard-error").textContent = message;
    $("dashboard-error").hidden = !message;
  }

  const call = window.dashboardCall;

  function progressText(s) {
    const p = s.progress;
    const parts = [];
    if (s.method !== "autonomous" && p.advice_budget) parts.push(`advice ${p.advice_given}/${p.advice_budget}`);
    if (s.condition) {
      // a pool's session practises for the next arrival: nobody has it yet
      const kind = s.preview ? "preview of " : s.pooled ? "kept for the next arrival in " : "";
      parts.push(`${kind}${s.condition}`);
    }
    if (s.outcome === "completed") parts.push("visit completed");
    if (s.method === "human" && !p.consented && !s.outcome && !s.pooled) {
      parts.push(s.declined ? "declined" : "not consented yet");
    }
    if (p.advice_wanted) parts.push("waiting for the participant");
    if (p.queued) parts.push(`advice done, queued for a trainer${p.queue_place ? ` (place ${p.queue_place})` : ""}`);
    if (p.stage === "train" || p.episode) parts.push(`episode ${p.episode}/${p.episodes}`);
    else if (p.stage && !p.queued && s.status === "running") parts.push(p.stage === "pretrain" ? "pretraining" : p.stage);
    if (p.last_episode_reward !== null && p.last_episode_reward !== undefined) {
      parts.push(`last ${p.last_episode_reward.toFixed(2)}`);
    }
    return parts.join(" · ") || "—";
  }

  function sessionRow(s, color) {
    const tr = document.createElement("tr");
    tr.dataset.session = s.id;
    const cells = Array.from({ length: 6 }, () => tr.appendChild(document.createElement("td")));
    cells[0].innerHTML = `<span class="swatch"></span><span class="session-id"></span><span class="muted small session-label"></span>`;
    if (color) cells[0].querySelector(".swatch").style.background = color;
    else cells[0].querySelector(".swatch").remove();
    cells[0].querySelector(".session-id").textContent = `#${s.id}`;
    cells[0].querySelector(".session-label").textContent = s.participant || s.label || `seed ${s.seed}`;
    const playback = cells[0].appendChild(document.createElement("a"));
    playback.className = "playback-link small";
    playback.href = `/dashboard/sessions/${s.id}/playback`;
    playback.textContent = "episodes";
    playback.title = "Play back a recorded episode";
    cells[1].textContent = s.method;
    cells[2].innerHTML = `<span class="badge"></span>`;
    const shown = s.status.replace("_", " ");
    cells[2].firstChild.textContent = shown;
    cells[2].firstChild.dataset.status = shown;
    if (s.status_detail) cells[2].firstChild.title = s.status_detail;
    if (s.node) {
      // where it trains: this machine, or a node of the Ray cluster
      const node = cells[2].appendChild(document.createElement("div"));
      node.className = "muted small session-node";
      node.textContent = `on ${s.node}`;
    }
    cells[3].textContent = progressText(s);
    if (s.pooled) {
      // its link goes to the next arrival at the study link, as the study's blocks assign:
      // handed out by hand, it would take a place outside the randomization
      cells[4].innerHTML = `<span class="muted">the study link's</span>`;
      cells[4].title = "The next arrival at the study link gets this session";
    } else if (s.participant_url) {
      cells[4].innerHTML = `<a class="link" target="_blank" rel="noopener"></a> <button class="copy" type="button">Copy</button>`;
      cells[4].firstChild.href = s.participant_url;
      cells[4].firstChild.textContent = "open";
      cells[4].querySelector(".copy").addEventListener("click", async (event) => {
        await navigator.clipboard.writeText(s.participant_url).catch(() => window.prompt("Participant link:", s.participant_url));
        event.target.textContent = "Copied";
        setTimeout(() => (event.target.textContent = "Copy"), 1500);
      });
    } else {
      cells[4].innerHTML = `<span class="muted">—</span>`;
    }
    // a pool's session is nobody's yet: the pools start and end it, not the researcher
    for (const command of s.pooled ? [] : COMMANDS[s.status] || []) {
      const button = document.createElement("button");
      button.type = "button";
      button.className = `command ${command}`;
      button.textContent = command;
      if (command === "start" && s.method === "human" && !s.progress.consented) {
        // The participant's link starts it after consent; the server refuses it too (409).
        button.disabled = true;
        button.title = "Waits for the participant's consent: their link starts the session.";
      }
      button.addEventListener("click", async () => {
        button.disabled = true;
        try {
          await call(`/dashboard/api/sessions/${s.id}/${command}`, { method: "POST" });
          showError("");
        } catch (e) {
          showError(`Session ${s.id}: ${e.message}`);
        }
        refresh();
      });
      cells[5].append(button);
    }
    return tr;
  }

  function showReport(section, report) {
    const box = section.querySelector(".report");
    box.querySelector(".report-when").textContent =
      `${report.sessions.length} sessions, ${report.n_episodes} episodes each, built ${new Date(report.created_at).toLocaleString()}` +
      (report.baseline ? `, against ${report.baseline}` : ", no baseline");
    const stamp = encodeURIComponent(report.created_at);
    box.querySelector(".report-md").href = `${report.report_url}?t=${stamp}`;
    box.querySelector(".report-zip").href = report.zip_url;
    box.querySelector(".report-methods tbody").replaceChildren(
      ...report.methods.map((m) => {
        const tr = document.createElement("tr");
        tr.dataset.method = m.method;
        // a percentage only against a positive baseline; else the difference in points
        const signed = (x, digits) => `${x >= 0 ? "+" : ""}${x.toFixed(digits)}`;
        const improvement = m.improvement_pct !== null ? `${signed(m.improvement_pct, 1)} %`
          : m.difference != null ? `${signed(m.difference, 2)} points` : "—";
        for (const text of [m.name, m.agents, m.episodes, m.R_T.toFixed(2), improvement]) {
          tr.appendChild(document.createElement("td")).textContent = text;
        }
        return tr;
      })
    );
    box.querySelector(".report-notes").replaceChildren(
      ...report.notes.map((note) => {
        const li = document.createElement("li");
        li.textContent = note;
        return li;
      })
    );
    box.querySelector(".report-figures").replaceChildren(
      ...report.files
        .filter((f) => f.kind === "figure" && f.name.endsWith(".png")) // SVG: the same figure
        .map((f) => {
          const link = document.createElement("a");
          link.href = `${f.url}?t=${stamp}`;
          link.target = "_blank";
          const img = link.appendChild(document.createElement("img"));
          img.src = link.href;
          img.alt = f.name;
          return link;
        })
    );
    box.dataset.builtAt = report.created_at;
    box.hidden = false;
  }

  function studySection(study) {
    let section = sections.get(study.id);
    if (section) return section;
    section = template.content.firstElementChild.cloneNode(true);
    section.dataset.study = study.id;
    section.querySelector(".export").href = `/dashboard/api/studies/${study.id}/export`;
    section.querySelector(".new-participant").addEventListener("submit", async (event) => {
      event.preventDefault();
      const input = event.target.elements.participant;
      try {
        await call(`/dashboard/api/studies/${study.id}/participants`, {
          method: "POST",
          body: JSON.stringify({ participant: input.value || null }),
        });
        input.value = "";
        showError("");
      } catch (e) {
        showError(`New participant: ${e.message}`);
      }
      refresh();
    });
    section.querySelector(".save-design").addEventListener("click", async () => {
      const box = section.querySelector(".design-json");
      const said = section.querySelector(".design-error");
      try {
        let design;
        try {
          design = JSON.parse(box.value);
        } catch (e) {
          throw new Error(`not JSON (${e.message})`);
        }
        const saved = await call(`/dashboard/api/studies/${study.id}/design`, {
          method: "POST",
          body: JSON.stringify({ design }),
        });
        box.value = JSON.stringify(saved.design, null, 2); // every default written out
        box.dataset.edited = "";
        said.hidden = true;
      } catch (e) {
        // beside the editor, where the researcher is looking, not at the top of the page
        said.textContent = `Not saved: ${e.message}`;
        said.hidden = false;
      }
      refresh();
    });
    section.querySelector(".design-json").addEventListener("input", (event) => (event.target.dataset.edited = "1"));
    section.querySelector(".preview").addEventListener("click", async () => {
      try {
        const made = await call(`/dashboard/api/studies/${study.id}/preview`, { method: "POST" });
        window.open(made.participant_url, "_blank", "noopener");
        showError("");
      } catch (e) {
        showError(`Preview of study ${study.id}: ${e.message}`);
      }
      refresh();
    });
    section.querySelector(".delete-previews").addEventListener("click", async () => {
      try {
        await call(`/dashboard/api/studies/${study.id}/preview`, { method: "DELETE" });
        showError("");
      } catch (e) {
        showError(`Previews of study ${study.id}: ${e.message}`);
      }
      refresh();
    });
    const buildButton = section.querySelector(".build-report");
    buildButton.addEventListener("click", async () => {
      buildButton.disabled = true;
      buildButton.textContent = "Building…";
      try {
        const baseline = section.querySelector(".report-baseline").value;
        showReport(
          section,
          await call(`/dashboard/api/studies/${study.id}/report`, { method: "POST", body: JSON.stringify({ baseline }) })
        );
        showError("");
      } catch (e) {
        showError(`Report of study ${study.id}: ${e.message}`);
      } finally {
        buildButton.disabled = false;
        // "Rebuild" only once there is a report to rebuild: a failed build made none.
        buildButton.textContent = section.querySelector(".report").dataset.builtAt ? "Rebuild report" : "Build report";
      }
    });
    sections.set(study.id, section);
    return section;
  }

  // The baseline's choices: auto (saying what it takes in this study), none, and each method
  // (an online study: each condition) the study's sessions have; the researcher's choice is
  // kept across polls.
  function showBaselines(study, section) {
    const select = section.querySelector(".report-baseline");
    const groups = study.design
      ? study.conditions.map((c) => c.condition)
      : [...new Set(study.sessions.filter((s) => !s.pooled).map((s) => s.method))].sort();
    select.options[0].textContent = groups.includes("autonomous")
      ? "auto (autonomous)"
      : "auto (none: no autonomous sessions)";
    const wanted = ["auto", "none", ...groups];
    const have = [...select.options].map((o) => o.value);
    if (wanted.join("\n") === have.join("\n")) return;
    const chosen = select.value;
    for (const option of [...select.options].slice(2)) option.remove();
    for (const group of groups) {
      const option = document.createElement("option");
      option.value = option.textContent = group;
      select.append(option);
    }
    select.value = wanted.includes(chosen) ? chosen : "auto";
  }

  // The report shown is the one the server has: refetched when another was built (here,
  // through the API or the command line), hidden when it is gone (a deleted session takes
  // its study's report with it), so no link on the page points at removed files.
  async function syncReport(study, section) {
    const box = section.querySelector(".report");
    const shown = box.dataset.builtAt || null;
    if (shown === study.report_built_at) return;
    const buildButton = section.querySelector(".build-report");
    // Removed between the overview and this request: hidden as if the overview had said so.
    const response = study.report_built_at
      ? await fetch(`/dashboard/api/studies/${study.id}/report`, { cache: "no-store" })
      : null;
    if (!response || !response.ok) {
      box.hidden = true;
      delete box.dataset.builtAt;
      buildButton.textContent = "Build report";
      return;
    }
    showReport(section, await response.json());
    buildButton.textContent = "Rebuild report";
  }

  async function refreshCurves(study, section, colors) {
    const curves = await call(`/dashboard/api/studies/${study.id}/curves`);
    const series = study.sessions
      .filter((s) => curves[s.id])
      .map((s) => ({ label: `#${s.id}`, color: colors[s.id], points: curves[s.id] }));
    const xMax = Math.max(1, ...study.sessions.filter((s) => curves[s.id]).map((s) => s.progress.episodes));
    window.drawCurves(section.querySelector("svg"), series, { xMax, empty: "No training episode yet" });
    const legend = section.querySelector(".legend");
    legend.replaceChildren();
    for (const s of series) {
      const item = document.createElement("span");
      item.innerHTML = `<span class="swatch"></span>`;
      item.firstChild.style.background = s.color;
      item.append(` ${s.label}`);
      legend.append(item);
    }
  }

  function showDesign(study, section) {
    const box = section.querySelector(".design-json");
    if (!box.dataset.edited && document.activeElement !== box) {
      box.value = study.design ? JSON.stringify(study.design, null, 2) : "";
    }
    const online = section.querySelector(".online");
    online.hidden = !study.design;
    if (!study.design) return;
    const link = online.querySelector(".join-link");
    link.href = link.textContent = study.join_url;
    online.querySelector(".conditions tbody").replaceChildren(
      ...study.conditions.map((c) => {
        const tr = document.createElement("tr");
        tr.dataset.condition = c.condition;
        for (const text of [c.condition, ...COUNTS.map((k) => c[k])]) {
          tr.appendChild(document.createElement("td")).textContent = text;
        }
        return tr;
      })
    );
  }

  async function refresh() {
    let studies;
    try {
      studies = await call("/dashboard/api/overview");
    } catch (e) {
      showError(`Could not load the studies: ${e.message}`);
      return;
    }
    const container = $("studies");
    if (!studies.length) {
      container.innerHTML = `<p class="muted">No study yet: create one above, or through the REST API.</p>`;
      return;
    }
    const wanted = [];
    for (const study of studies) {
      const section = studySection(study);
      section.querySelector(".study-name").textContent = study.name;
      section.querySelector(".study-description").textContent = study.description;
      showDesign(study, section);
      // the participants' sessions, then those a pool keeps for the next arrivals
      const people = study.sessions.filter((s) => !s.pooled);
      const pooled = study.sessions.filter((s) => s.pooled);
      const colors = {};
      people.forEach((s, i) => (colors[s.id] = colorOf(i)));
      const tbody = section.querySelector("table.sessions tbody");
      tbody.replaceChildren(...[...people, ...pooled].map((s) => sessionRow(s, colors[s.id])));
      if (!study.sessions.length) {
        tbody.innerHTML = `<tr><td colspan="6" class="muted">No session yet. “New participant link” makes a human session.</td></tr>`;
      }
      refreshCurves(study, section, colors).catch((e) => showError(`Curves: ${e.message}`));
      showBaselines(study, section);
      syncReport(study, section).catch((e) => showError(`Report of study ${study.id}: ${e.message}`));
      wanted.push(section);
    }
    container.replaceChildren(...wanted);
  }

  $("new-study").addEventListener("submit", async (event) => {
    event.preventDefault();
    const input = event.target.elements.name;
    try {
      await call("/dashboard/api/studies", { method: "POST", body: JSON.stringify({ name: input.value }) });
      input.value = "";
      showError("");
    } catch (e) {
      showError(`New study: ${e.message}`);
    }
    refresh();
  });

  refresh();
  setInterval(refresh, 3000);
})();
