// A small SVG line plot of collected reward per episode, shared by the thank-you page
// and the dashboard (no external library: nothing is downloaded at run time).
"use strict";
window.drawCurves = (svg, series, options = {}) => {
  const NS = "http://www.w3.org/2000/svg";
  const [, , width, height] = svg.getAttribute("viewBox").split(" ").map(Number);
  const margin = { left: 52, right: 16, top: 14, bottom: 40 };
  const w = width - margin.left - margin.right;
  const h = height - margin.top - margin.bottom;
  const all = series.flatMap((s) => s.points);
  const xMax = Math.max(options.xMax || 1, ...all.map((p) => p[0]));
  let yMin = Math.min(-1, ...all.map((p) => p[1]));
  let yMax = Math.max(3, ...all.map((p) => p[1]));
  const step = niceStep((yMax - yMin) / 5);
  yMin = Math.floor(yMin / step) * step;
  yMax = Math.ceil(yMax / step) * step;
  const x = (v) => margin.left + (w * (v - 1)) / Math.max(1, xMax - 1);
  const y = (v) => margin.top + h - (h * (v - yMin)) / (yMax - yMin);

  function niceStep(raw) {
    const power = 10 ** Math.floor(Math.log10(raw));
    return [1, 2, 5, 10].map((m) => m * power).find((s) => s >= raw);
  }
  function add(tag, attrs, parent = svg, text) {
    const el = document.createElementNS(NS, tag);
    for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
    if (text !== undefined) el.textContent = text;
    parent.append(el);
    return el;
  }

  svg.replaceChildren();
  for (let v = yMin; v <= yMax + 1e-9; v += step) {
    add("line", { x1: margin.left, x2: margin.left + w, y1: y(v), y2: y(v), class: v === 0 ? "axis zero" : "grid" });
    add("text", { x: margin.left - 8, y: y(v) + 4, class: "tick", "text-anchor": "end" }, svg, +v.toFixed(2));
  }
  const xStep = niceStep(Math.max(1, (xMax - 1) / 6));
  for (let v = 1; v <= xMax; v += v === 1 && xStep > 1 ? xStep - 1 : xStep) {
    add("text", { x: x(v), y: margin.top + h + 18, class: "tick", "text-anchor": "middle" }, svg, v);
  }
  add("line", { x1: margin.left, x2: margin.left, y1: margin.top, y2: margin.top + h, class: "axis" });
  add("text", { x: margin.left + w / 2, y: height - 4, class: "label", "text-anchor": "middle" }, svg, options.xLabel || "round (episode)");
  add("text", { x: 12, y: margin.top + h / 2, class: "label", "text-anchor": "middle", transform: `rotate(-90 12 ${margin.top + h / 2})` }, svg, options.yLabel || "points collected");

  for (const s of series) {
    if (!s.points.length) continue;
    const d = s.points.map((p, i) => `${i ? "L" : "M"}${x(p[0]).toFixed(1)},${y(p[1]).toFixed(1)}`).join("");
    add("path", { d, class: "series", stroke: s.color || "var(--accent)" });
    if (s.points.length <= 120) {
      for (const p of s.points) add("circle", { cx: x(p[0]), cy: y(p[1]), r: 3, fill: s.color || "var(--accent)", class: "dot" });
    }
  }
  if (!all.length) {
    add("text", { x: margin.left + w / 2, y: margin.top + h / 2, class: "empty", "text-anchor": "middle" }, svg, options.empty || "No finished round yet");
  }
};
