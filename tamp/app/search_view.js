/* The search view's script (tamp/app/search_view.py inlines it). No library, no network: it reads the record
   from the page's JSON element and draws it with the DOM and SVG. Every text from the record goes in as text
   (textContent, attributes), or escaped (`esc`) in the tree's rows, which are built as one HTML string for speed. The page's state lives in its address (#round=1&select=n17&filter=path
   &t=40&state=2&expand=all), so a view can be linked and a test or a screenshot can open it directly. */
(function () {
"use strict";
const DATA = JSON.parse(document.getElementById("tamp-search-data").textContent);
const REC = DATA.record || {};
const ROUNDS = Array.isArray(REC.rounds) ? REC.rounds : [];
const PROBLEM = REC.problem || {};
const NAMES = (REC.symbols && REC.symbols.names) || {};
const X_INIT = Array.isArray(PROBLEM.X_init) ? PROBLEM.X_init : [];
const LARGE = X_INIT.map(function (x) { return x.length > 4 && x[4] === 1; });  // a 5 x 25 x 5 cm bar along y
const SMALL_M = 0.05, BAR_M = 0.25, OFFSET_M = 0.075;
const COLORS = ["#d1495b", "#2e86ab", "#edae49", "#66a182", "#8d6cab", "#f08a4b", "#3d5a80", "#9c6644"];

const ORIGINS = {
  "planned": "the round planned afresh from the scene it observed",
  "kept on course": "the scene matched what the previous round predicted, so its plan's next step was kept",
  "kept by rollout": "the Dynamics Model's rollout of the rest of the previous plan from the observed scene " +
                     "still reached the goal, so that plan was kept",
  "widened search": "no plan was found within the usual budget, so the round searched again more widely",
  "toward the closest state": "no plan reached the goal: the round took the one that ends closest to it",
};
const TIPS = {
  count: "how many of the sampled symbolic domains gave this plan (more = the learned symbols agree more)",
  probability: "the plan's probability under the learned operators' effects",
  error: "the Dynamics Model's rollout of the plan from the observed scene, against the goal: how far its " +
         "predicted final scene lies from the goal (largest over blocks)",
  verified: "whether the Dynamics Model's rollout reached the goal within tolerance (a plan that does not " +
            "verify is dropped)",
  kinematics: "the kinematic check of each action in its predicted scene: whether the arm can grasp and place " +
              "it (a grasp exists, inverse kinematics has a solution, no collision)",
  order: "expansion order: the node was the k-th the search took off its queue (-- : never expanded)",
  g: "g: the cost of the actions from the start to this node",
  h: "h: the heuristic's estimate of the cost still to go to the goal",
  miss: "how far the executed step's blocks landed from the Dynamics Model's prediction (largest over blocks)",
  ik: "IK branch: which of the arm's inverse-kinematics solutions the motion used",
  planner: "motion planner: 'direct' when the straight joint-space move is collision-free, else the sampling " +
           "planner (e.g. rrtconnect) that searched around obstacles",
};

// ---------- small helpers ----------
function el(tag, props, kids) {
  const e = document.createElement(tag);
  if (props) for (const k in props) {
    const v = props[k];
    if (v === null || v === undefined || v === false) continue;
    if (k === "text") e.textContent = String(v);
    else if (k === "cls") e.className = v;
    else if (k.slice(0, 2) === "on") e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? "" : String(v));
  }
  if (kids) for (const c of kids) if (c !== null && c !== undefined && c !== false)
    e.appendChild(typeof c === "string" ? document.createTextNode(c) : c);
  return e;
}
function tip(text, title) { return el("span", {cls: "tip", title: title, text: text}); }
function chip(text, kind, title) { return el("span", {cls: "chip " + kind, title: title, text: text}); }
function num(v, digits) { return typeof v === "number" && isFinite(v) ? v.toFixed(digits) : "--"; }
function cm(m) { return typeof m === "number" && isFinite(m) ? (m * 100).toFixed(1) + " cm" : "--"; }
function offset(k) { return k === 0 ? "centre" : (k > 0 ? "+" : "\u2212") + (Math.abs(k) * OFFSET_M * 100) + " cm"; }
function actionText(a) {
  if (!Array.isArray(a) || a.length < 4) return "start";
  return "pick " + a[0] + " at " + offset(a[1]) + " \u2192 place on " + a[2] + " at " + offset(a[3]);
}
function shortAction(a) {   // for the tree's rows: "pick 1 (+7.5) → on 0 (−7.5)"
  if (!Array.isArray(a) || a.length < 4) return "start";
  const o = function (k) { return k === 0 ? "0" : (k > 0 ? "+" : "\u2212") + Math.abs(k) * OFFSET_M * 100; };
  return "pick " + a[0] + " (" + o(a[1]) + ") \u2192 on " + a[2] + " (" + o(a[3]) + ")";
}
const ACTION_TIP = "pick i at o: grasp block i at offset o along it; place on j at o: release it on block j " +
                   "at offset o (offsets are -7.5, 0 or +7.5 cm)";
function factTitle(fact) {
  const key = String(fact).split("(")[0];
  return NAMES[fact] || NAMES[key] || null;
}
function sameAction(a, b) { return JSON.stringify(a) === JSON.stringify(b); }
function brief(v) {   // a number, string or small object as short text: {"solved": 99, "stopped": 1} -> solved 99, stopped 1
  if (typeof v === "number") return Number.isInteger(v) ? String(v) : v.toFixed(3);
  if (v === null || v === undefined) return "--";
  if (typeof v === "object" && !Array.isArray(v)) {
    const keys = Object.keys(v);
    return keys.length ? keys.map(function (k) { return k + " " + brief(v[k]); }).join(", ") : "none";
  }
  return typeof v === "string" ? v : JSON.stringify(v);
}
function motions(planner) {   // "approach direct, descend direct, ..." -> "direct x7"; the full text is its title
  if (typeof planner !== "string" || planner.indexOf(",") < 0) return planner || "--";
  const counts = new Map();
  for (const part of planner.split(",")) {
    const words = part.trim().split(" ");
    const name = words[words.length - 1];
    counts.set(name, (counts.get(name) || 0) + 1);
  }
  return Array.from(counts).map(function (c) { return c[0] + " \u00d7" + c[1]; }).join(", ");
}

// ---------- the page's state, kept in its address ----------
const S = {round: 0, select: null, filter: "all", t: null, state: null, expandAll: false};
function readHash() {
  const q = new URLSearchParams(location.hash.replace(/^#/, ""));
  const r = parseInt(q.get("round") || "0", 10);
  S.round = isFinite(r) && r >= 0 && r < ROUNDS.length ? r : 0;
  S.select = q.get("select");
  S.filter = q.get("filter") || "all";
  const count = function (key) { const v = parseInt(q.get(key), 10); return v >= 0 ? v : null; };
  S.t = count("t");
  S.state = count("state");
  S.expandAll = q.get("expand") === "all";
}
function writeHash() {
  const q = new URLSearchParams();
  q.set("round", String(S.round));
  if (S.select) q.set("select", S.select);
  if (S.filter !== "all") q.set("filter", S.filter);
  if (S.t !== null && tree && S.t < tree.T) q.set("t", String(S.t));
  if (S.state !== null) q.set("state", String(S.state));
  history.replaceState(null, "", "#" + q.toString());
}

// ---------- Level 2's tree ----------
let tree = null;      // the current round's tree: maps and the expansion sequence
let expanded = new Set();
function buildTree(level2) {
  const nodes = (level2 && Array.isArray(level2.nodes)) ? level2.nodes : [];
  const byId = new Map(), kids = new Map(), roots = [];
  for (const n of nodes) { byId.set(n.id, n); kids.set(n.id, []); }
  for (const n of nodes) {
    if (n.parent === null || n.parent === undefined || !byId.has(n.parent)) roots.push(n);
    else kids.get(n.parent).push(n);
  }
  const key = function (n) { return n.order === null || n.order === undefined ? Infinity : n.order; };
  const byOrder = function (a, b) { return key(a) - key(b) || (a.id < b.id ? -1 : a.id > b.id ? 1 : 0); };
  for (const list of kids.values()) list.sort(byOrder);
  roots.sort(byOrder);
  const sequence = nodes.filter(function (n) { return key(n) !== Infinity; }).sort(byOrder);
  const rank = new Map();
  sequence.forEach(function (n, i) { rank.set(n.id, i); });
  const found = Array.isArray(level2 && level2.path) && level2.path.length;
  const path = new Set(found ? level2.path : (Array.isArray(level2 && level2.closest) ? level2.closest : []));
  const reasons = new Map();
  for (const n of nodes) if (rejected(n)) reasons.set(n.verdict, (reasons.get(n.verdict) || 0) + 1);
  return {byId: byId, kids: kids, roots: roots, sequence: sequence, rank: rank, path: path, reasons: reasons,
          T: sequence.length, level2: level2, pathName: found ? "the path found" : "the path to the closest state"};
}
function rejected(n) { return n.verdict !== undefined && n.verdict !== null && n.verdict !== "ok"; }
function generated(n) {   // made by one of the first S.t expansions (the timeline)
  if (S.t === null || S.t >= tree.T) return true;
  if (n.parent === null || n.parent === undefined || !tree.byId.has(n.parent)) return true;
  const r = tree.rank.get(n.parent);
  return r !== undefined && r < S.t;
}
function ancestors(id, into) {   // (a damaged record's cycle of parents ends after as many steps as nodes)
  let n = tree.byId.get(id), steps = 0;
  while (n && n.parent !== null && n.parent !== undefined && tree.byId.has(n.parent) && steps++ < tree.byId.size) {
    into.add(n.parent);
    n = tree.byId.get(n.parent);
  }
  return into;
}
function matches(n) {
  if (S.filter === "path") return tree.path.has(n.id);
  if (S.filter === "rejected") return rejected(n);
  if (S.filter.indexOf("reason:") === 0) return n.verdict === S.filter.slice(7);
  return true;
}
let shown = null;     // with a filter: the nodes that match and their ancestors
function applyFilter() {
  shown = null;
  if (S.filter === "all") return;
  shown = new Set();
  expanded = new Set();
  for (const n of tree.byId.values()) if (matches(n)) { shown.add(n.id); ancestors(n.id, shown); }
  for (const id of shown) ancestors(id, expanded);
}
const ESCAPED = {"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"};
function esc(text) { return String(text).replace(/[&<>"']/g, function (c) { return ESCAPED[c]; }); }
function treeRow(n, depth) {   // one row as HTML (a large tree builds faster as one string), every text escaped
  let visible = 0;
  for (const c of tree.kids.get(n.id)) if ((!shown || shown.has(c.id)) && generated(c)) visible++;
  const open = expanded.has(n.id);
  const classes = ["row"];
  if (tree.path.has(n.id)) classes.push("path");
  if (rejected(n)) classes.push("rejected");
  if (S.t !== null && S.t > 0 && S.t <= tree.T && tree.sequence[S.t - 1] === n) classes.push("current");
  if (S.select === "n" + n.id) classes.push("selected");
  let rank = tree.rank.get(n.id);
  if (rank !== undefined && S.t !== null && rank >= S.t) rank = undefined;   // not yet expanded on the timeline
  const toggle = visible ? '<button class="tg" data-toggle="1" aria-expanded="' + open + '" title="' +
    (open ? "collapse" : "expand") + " its " + visible + ' successor(s)">' + (open ? "\u25be" : "\u25b8") + "</button>"
    : '<span class="tg">\u00b7</span>';
  const verdict = rejected(n)
    ? '<span class="chip bad" title="' + esc(n.reason || "rejected: " + n.verdict) + '">' + esc(n.verdict) + "</span>"
    : '<span class="chip ok" title="the edge to this node passed the kinematic check">ok</span>';
  return '<div class="' + classes.join(" ") + '" data-id="' + esc(JSON.stringify(n.id)) + '" style="padding-left:' +
    (4 + depth * 16) + 'px"' + (n.reason ? ' title="' + esc(n.reason) + '"' : "") + ">" + toggle +
    '<span class="id">#' + esc(n.id) + '</span><span class="ord">' + (rank === undefined ? "--" : "exp " + (rank + 1)) +
    '</span><span class="act" title="' + esc(actionText(n.action)) + '">' + esc(shortAction(n.action)) +
    '</span><span class="gh">g ' + num(n.g, 2) + "  h " + num(n.h, 2) + "</span>" + verdict + "</div>";
}
function renderTree() {
  const box = document.getElementById("tree");
  if (!box || !tree) return;
  const html = [];
  let rows = 0;
  const stack = [];
  for (let i = tree.roots.length - 1; i >= 0; i--) stack.push([tree.roots[i], 0]);
  while (stack.length) {
    const top = stack.pop(), n = top[0], depth = top[1];
    if ((shown && !shown.has(n.id)) || !generated(n)) continue;
    html.push(treeRow(n, depth));
    rows++;
    if (expanded.has(n.id)) {
      const list = tree.kids.get(n.id);
      for (let i = list.length - 1; i >= 0; i--) stack.push([list[i], depth + 1]);
    }
  }
  box.innerHTML = html.join("");
  if (!rows) box.appendChild(el("div", {cls: "empty", text: "no node matches the filter at this point of the timeline"}));
  const count = document.getElementById("tree-count");
  if (count) count.textContent = rows + " of " + tree.byId.size + " nodes in view";
  const slider = document.getElementById("timeline-label");
  if (slider) slider.textContent = S.t === null || S.t >= tree.T ? "all " + tree.T + " expansions"
    : "after expansion " + S.t + " of " + tree.T;
}
function onTreeClick(event) {
  const row = event.target.closest(".row");
  if (!row) return;
  const id = Number(row.getAttribute("data-id"));
  if (event.target.closest("[data-toggle]")) {
    if (expanded.has(id)) expanded.delete(id); else expanded.add(id);
    renderTree();
    return;
  }
  select("n" + id);
}
function setTimeline(t) {
  S.t = Math.max(0, Math.min(tree.T, t));
  const slider = document.getElementById("timeline");
  if (slider) slider.value = String(S.t);
  if (S.t > 0 && S.t < tree.T) {
    const n = tree.sequence[S.t - 1];
    ancestors(n.id, expanded);
    expanded.add(n.id);
    if (shown) { shown.add(n.id); ancestors(n.id, shown); for (const c of tree.kids.get(n.id)) shown.add(c.id); }
    S.select = "n" + n.id;
    S.state = null;
    renderTree();
    renderScene();
    const row = document.querySelector('#tree .row[data-id="' + CSS.escape(JSON.stringify(n.id)) + '"]');
    if (row) row.scrollIntoView({block: "nearest"});
  } else renderTree();
  writeHash();
}
let playing = null;
function play(button) {
  if (playing !== null) { clearInterval(playing); playing = null; button.textContent = "\u25b6 replay"; return; }
  if (S.t === null || S.t >= tree.T) setTimeline(0);
  const step = Math.max(1, Math.ceil(tree.T / 300));
  button.textContent = "\u275a\u275a pause";
  playing = setInterval(function () {
    setTimeline((S.t || 0) + step);
    if (S.t >= tree.T) { clearInterval(playing); playing = null; button.textContent = "\u25b6 replay"; }
  }, 40);
}

// ---------- scenes: top (x-y) and side (y-z) views in SVG, sharing y ----------
const SVGNS = "http://www.w3.org/2000/svg";
function svg(tag, attrs, kids) {
  const e = document.createElementNS(SVGNS, tag);
  for (const k in attrs) e.setAttribute(k, String(attrs[k]));
  if (kids) for (const c of kids) e.appendChild(c);
  return e;
}
function extent(i, axis) {   // half size of block i along axis 0 (x), 1 (y), 2 (z), metres
  return (axis === 1 && LARGE[i] ? BAR_M : SMALL_M) / 2;
}
function bounds(scenes) {
  const b = {x: [Infinity, -Infinity], y: [Infinity, -Infinity], z: [0, -Infinity]};
  for (const X of scenes) if (X) X.forEach(function (p, i) {
    ["x", "y", "z"].forEach(function (k, a) {
      b[k][0] = Math.min(b[k][0], p[a] - extent(i, a));
      b[k][1] = Math.max(b[k][1], p[a] + extent(i, a));
    });
  });
  if (!isFinite(b.x[0])) return {x: [-0.3, 0.3], y: [-0.3, 0.3], z: [0, 0.2]};
  const widen = function (r, least) {   // padded, and at least `least` metres wide about its middle
    const mid = (r[0] + r[1]) / 2, half = Math.max((r[1] - r[0]) / 2 + 0.04, least / 2);
    return [mid - half, mid + half];
  };
  b.x = widen(b.x, 0.35); b.y = widen(b.y, 0.35); b.z = [0, Math.max(b.z[1] + 0.04, 0.2)];
  return b;
}
function view(X, ghost, b, side) {
  // Both views share the horizontal axis, y, drawn leftward (+y is the robot's left), as an engineering drawing
  // does: the top view is seen from above with x (away from the robot) up, the side view seen from the robot, z up.
  const axisV = side ? 2 : 0, V = side ? b.z : b.x;
  const mm = 1000, w = (b.y[1] - b.y[0]) * mm, ht = (V[1] - V[0]) * mm;
  const sx = function (y) { return (b.y[1] - y) * mm; }, sy = function (v) { return (V[1] - v) * mm; };
  const kids = [];
  if (side) kids.push(svg("line", {x1: 0, x2: w, y1: sy(0), y2: sy(0), stroke: "#999", "stroke-width": 3}));
  const box = function (p, i, style) {
    const hw = extent(i, 1), hh = extent(i, axisV);
    return svg("rect", Object.assign({x: sx(p[1] + hw), y: sy(p[axisV] + hh), width: 2 * hw * mm,
                                      height: 2 * hh * mm, rx: 3}, style));
  };
  if (ghost) ghost.forEach(function (p, i) {
    kids.push(box(p, i, {fill: "none", stroke: COLORS[i % COLORS.length], "stroke-width": 4,
                         "stroke-dasharray": "10 8"}));
  });
  if (X) {
    const order = X.map(function (p, i) { return i; });
    order.sort(function (a, c) { return side ? X[c][0] - X[a][0] : X[a][2] - X[c][2]; });   // nearest/highest last
    for (const i of order) {
      const p = X[i];
      kids.push(box(p, i, {fill: COLORS[i % COLORS.length], stroke: "#222", "stroke-width": 2, "fill-opacity": 0.9}));
      const t = svg("text", {x: sx(p[1]), y: sy(p[axisV]) + 12, "text-anchor": "middle", "font-size": 34,
                             "font-weight": 700, fill: "#fff"});
      t.textContent = String(i);
      kids.push(t);
    }
  }
  const bar = svg("g", {}, [svg("line", {x1: 10, x2: 110, y1: ht - 12, y2: ht - 12, stroke: "#444", "stroke-width": 4}),
                            svg("text", {x: 60, y: ht - 20, "text-anchor": "middle", "font-size": 26, fill: "#444"})]);
  bar.lastChild.textContent = "10 cm";
  kids.push(bar);
  return svg("svg", {viewBox: "0 0 " + w.toFixed(0) + " " + ht.toFixed(0), role: "img", "class": side ? "side" : "top",
                     "aria-label": side ? "side view, seen from the robot: y to the left, z up"
                       : "top view, seen from above: y to the left, x away from the robot (up)"}, kids);
}
function sceneColumn(title, X, ghost, b, caption, cls) {
  return el("div", {cls: "scene " + (cls || "")}, [
    el("h3", {text: title}),
    X ? view(X, ghost, b, false) : el("div", {cls: "empty", text: "not recorded"}),
    X ? view(X, ghost, b, true) : null,
    caption ? el("div", {cls: "cap", text: caption}) : null,
  ]);
}
function xyz(rows) { return Array.isArray(rows) ? rows.map(function (r) { return [r[0], r[1], r[2]]; }) : null; }
function worst(A, B) {
  if (!A || !B) return null;
  let m = 0;
  for (let i = 0; i < Math.min(A.length, B.length); i++)
    m = Math.max(m, Math.hypot(A[i][0] - B[i][0], A[i][1] - B[i][1], A[i][2] - B[i][2]));
  return m;
}
function selection() {   // {title, X, caption, facts, states, observed, observedTitle}
  const rd = ROUNDS[S.round], sel = S.select;
  const observed = xyz(rd.X_observed);
  if (!sel) return null;
  if (sel === "x" && rd.executed) {
    const e = rd.executed;
    return {title: "predicted after the step", X: xyz(e.predicted), observed: xyz(e.observed),
            observedTitle: "observed after the step",
            caption: "executed " + actionText(e.action) + "; landed " + cm(e.miss_m) + " from the prediction"};
  }
  if (sel[0] === "c") {
    const cands = (rd.level1 && rd.level1.candidates) || [];
    const c = cands[parseInt(sel.slice(1), 10)];
    if (!c) return null;
    const states = Array.isArray(c.predicted) ? c.predicted : null;
    const n = states ? states.length : (Array.isArray(c.facts) ? c.facts.length : 0);
    const k = S.state === null || !(S.state >= 0 && S.state < n) ? n - 1 : S.state;
    const what = k === 0 ? "at the start" : "after action " + k + " (" + actionText((c.actions || [])[k - 1]) + ")";
    return {title: "candidate " + (c.rank !== undefined ? c.rank : sel.slice(1)) + " predicted " +
                   (k === 0 ? "start" : "after action " + k),
            X: states ? xyz(states[k]) : null, observed: observed, observedTitle: "observed (round start)",
            caption: "Level 1 candidate, state " + what + (states ? "" : " (no predicted scene: the Dynamics Model " +
                     "did not roll this plan out)"), facts: Array.isArray(c.facts) ? c.facts[k] : null,
            states: n, k: k, candidate: c};
  }
  if (sel[0] === "n" && tree) {
    const n = tree.byId.get(Number(sel.slice(1)));
    if (!n) return null;
    const verdict = rejected(n) ? "rejected: " + n.verdict + (n.reason ? " (" + n.reason + ")" : "") : "ok";
    return {title: "node #" + n.id + " predicted", X: xyz(n.X), observed: observed,
            observedTitle: "observed (round start)",
            caption: "Level 2 node #" + n.id + ": " + actionText(n.action) + "; g " + num(n.g, 2) + ", h " +
                     num(n.h, 2) + "; " + verdict +
                     (n.duplicates ? "; " + n.duplicates + " of its successors reached scenes already seen" : "") +
                     (n.X ? "" : " (the record keeps no scene for this node)")};
  }
  return null;
}
function renderScene() {
  const box = document.getElementById("scene");
  if (!box) return;
  const rd = ROUNDS[S.round], s = selection();
  const goal = xyz(PROBLEM.X_goal);
  const observed = s ? s.observed : xyz(rd.X_observed);
  const predicted = s ? s.X : null;
  const b = bounds([predicted, goal, observed]);
  const kids = [el("h2", {text: "Scenes"}),
    el("p", {cls: "muted", text: "Each scene from above (the robot below it, x away from it) over the same seen from the " +
      "robot (z up); +y is the robot's left. Coloured boxes are blocks, numbered as in the problem; dashed outlines " +
      "are, in the predicted scene, each block's goal and, in the observed scene, where the prediction put it."})];
  if (!s) kids.push(el("p", {cls: "empty", text: "Click a Level 1 candidate, a Level 2 node or the executed step " +
                                                   "to draw its predicted scene here."}));
  else kids.push(el("p", {cls: "caption", id: "scene-caption", text: s.caption}));
  if (s && s.states > 1) {
    const stepper = el("div", {cls: "stepper"}, [el("span", {text: "symbolic state:"})]);
    for (let k = 0; k < s.states; k++) stepper.appendChild(el("button", {
      "aria-pressed": k === s.k ? "true" : "false", text: k === 0 ? "start" : "after " + k,
      onclick: function () { S.state = k; writeHash(); renderScene(); }}));
    kids.push(stepper);
  }
  const distance = worst(predicted, goal);
  kids.push(el("div", {cls: "scenes"}, [
    sceneColumn(s ? s.title : "predicted", predicted, goal, b,
                distance === null ? null : "largest distance to the goal: " + cm(distance), "predicted"),
    sceneColumn("goal", goal, null, b, null, "goal"),
    sceneColumn(s ? s.observedTitle : "observed (round start)", observed, predicted || goal, b,
                S.select === "x" && rd.executed ? "largest distance to the prediction: " + cm(rd.executed.miss_m)
                  : null, "observed"),
  ]));
  if (s && Array.isArray(s.facts)) {
    kids.push(el("h3", {text: "facts in this symbolic state"}));
    kids.push(factList(s.facts));
  }
  box.replaceChildren.apply(box, kids);
}
function factList(facts) {
  if (!facts.length) return el("div", {cls: "facts empty", text: "no named fact holds"});
  return el("div", {cls: "facts"}, facts.map(function (f, i) {
    const t = factTitle(f);
    return el("span", {cls: t ? "tip" : null, title: t, text: String(f) + (i < facts.length - 1 ? "; " : "")});
  }));
}

// ---------- the panels ----------
function select(key) {
  S.select = key; S.state = null;
  document.querySelectorAll(".selected").forEach(function (e) { e.classList.remove("selected"); });
  if (key && key[0] === "n") {
    const row = document.querySelector('#tree .row[data-id="' + CSS.escape(key.slice(1)) + '"]');
    if (row) row.classList.add("selected");
  }
  if (key && key[0] === "c") {
    const card = document.querySelector('.cand[data-index="' + key.slice(1) + '"]');
    if (card) card.classList.add("selected");
  }
  writeHash();
  renderScene();
}
function header() {
  const cfg = REC.config || {};
  const name = PROBLEM.name || "unnamed problem";
  const legend = el("details", {cls: "legend"}, [el("summary", {text: "How to read this page"}),
    el("div", {cls: "legend-grid"}, [
      el("div", {}, [chip("chosen", "chosen"), " the plan the round executed"]),
      el("div", {}, [chip("verified", "ok"), " / ", chip("not verified", "bad"), " ", tip("verified", TIPS.verified)]),
      el("div", {}, [chip("ok", "ok"), " / ", chip("IK", "bad"), " ", tip("kinematic verdict", TIPS.kinematics)]),
      el("div", {}, [el("span", {cls: "row path", style: "display:inline-flex;padding:0 6px", text: "green row"}),
                     " a node on the path Level 2 found"]),
      el("div", {}, [el("span", {style: "color:#b3261e", text: "red action"}), " a successor the search rejected, " +
                     "with its reason (hover the row)"]),
      el("div", {}, [tip("exp k", TIPS.order), ", ", tip("g", TIPS.g), ", ", tip("h", TIPS.h)]),
      el("div", {}, [tip("pick i at o \u2192 place on j at o", ACTION_TIP), "; in the tree ",
                     tip("pick i (o) \u2192 on j (o)", ACTION_TIP), ", o in cm"]),
      el("div", {}, ["blocks: 5 cm cubes and 5 \u00d7 25 cm bars along y; ", tip("miss", TIPS.miss)]),
    ])]);
  const facts = [["rounds", ROUNDS.length], ["blocks", X_INIT.length]];
  const l1cfg = cfg.level1 || cfg, l2cfg = cfg.search || cfg;
  if (cfg.method !== undefined) facts.push(["method", cfg.method]);
  if (l1cfg.n_domains !== undefined) facts.push(["sampled domains", l1cfg.n_domains]);
  if (l2cfg.max_expansions !== undefined) facts.push(["Level 2 budget", l2cfg.max_expansions + " expansions"]);
  if (PROBLEM.source) facts.push(["from", PROBLEM.source]);
  return el("header", {}, [
    el("h1", {text: "What the planner considered: " + name}),
    el("div", {cls: "kv sub"}, facts.map(function (f) { return el("span", {}, [f[0] + ": ", el("b", {text: String(f[1])})]); })),
    legend,
    el("details", {cls: "legend"}, [el("summary", {text: "configuration"}),
      el("pre", {style: "white-space:pre-wrap;font-size:12px", text: JSON.stringify(cfg, null, 1)})]),
  ]);
}
function tabs() {
  return el("nav", {cls: "tabs", role: "tablist"}, ROUNDS.map(function (r, i) {
    const e = r.executed;
    return el("button", {role: "tab", "aria-selected": i === S.round ? "true" : "false", "data-round": String(i),
                         title: ORIGINS[r.origin] || null,
                         onclick: function () { if (i !== S.round) { S.round = i; S.select = null; S.t = null;
                           S.state = null; S.filter = "all"; S.expandAll = false; renderRound(); } }}, [
      "Round " + (r.index !== undefined ? r.index : i),
      el("small", {text: (r.origin || "") + (e ? "; missed by " + cm(e.miss_m) : "")}),
    ]);
  }));
}
function roundSummary(r) {
  const e = r.executed;
  const kids = [el("div", {cls: "kv"}, [
    el("span", {}, ["how it got its plan: ", tip(r.origin || "--", ORIGINS[r.origin] || "")]),
    r.method ? el("span", {}, ["method: ", el("b", {text: r.method})]) : null,
    el("span", {}, ["plan from: ", el("b", {text: r.level ? "Level " + r.level : "no level (no plan)"})]),
    r.timings_s ? el("span", {text: "time: " + Object.keys(r.timings_s).map(function (k) {
      return k + " " + num(r.timings_s[k], 2) + " s"; }).join(", ")}) : null,
  ])];
  if (r.why) kids.push(el("div", {text: "why: " + r.why}));
  if (typeof r.predicted_error_m === "number") kids.push(el("div", {}, [tip("predicted to end", "where the Dynamics " +
    "Model's rollout of the plan from the observed scene ends, against the goal (largest over blocks)"),
    " " + cm(r.predicted_error_m) + " from the goal"]));
  if (r.rejected && typeof r.rejected === "object") kids.push(el("div", {}, [tip("rejected by the kinematic check",
    TIPS.kinematics), ": " + Object.keys(r.rejected).map(function (k) { return k + ": " + brief(r.rejected[k]); }).join("; ")]));
  if (Array.isArray(r.reasons) && r.reasons.length) kids.push(el("div", {cls: "muted", text: r.reasons.join("; ")}));
  if (e) kids.push(el("div", {id: "executed"}, ["executed step: ", el("b", {text: actionText(e.action)}), "; ",
    tip("landed " + cm(e.miss_m) + " from the prediction", TIPS.miss), " ",
    el("button", {cls: "link", id: "show-executed", text: "show the scenes", onclick: function () { select("x"); }})]));
  else kids.push(el("div", {cls: "muted", text: "no step executed in this round"}));
  return el("section", {cls: "card round-summary"}, kids);
}
function level1Panel(r) {
  const l1 = r.level1;
  const box = el("section", {cls: "card", id: "level1"}, [el("h2", {text: "Level 1: ranked symbolic plans"})]);
  if (!l1) { box.appendChild(el("p", {cls: "empty", text: "Level 1 did not run in this round."})); return box; }
  if (l1.stats) box.appendChild(el("div", {cls: "kv muted"}, Object.keys(l1.stats).filter(function (k) {
    return l1.stats[k] !== null; }).map(function (k) { return el("span", {text: k.replace(/_/g, " ") + ": " + brief(l1.stats[k])}); })));
  const cands = Array.isArray(l1.candidates) ? l1.candidates : [];
  if (!cands.length) box.appendChild(el("p", {cls: "empty", text: "no symbolic plan was found."}));
  box.appendChild(el("div", {cls: "cands"}, cands.map(function (c, i) {
    const kin = Array.isArray(c.kinematics) ? c.kinematics : [];
    const facts = Array.isArray(c.facts) ? c.facts : [];
    return el("div", {cls: "cand" + (c.chosen ? " chosen" : "") + (S.select === "c" + i ? " selected" : ""),
                      "data-index": String(i), onclick: function (ev) {
                        if (!ev.target.closest("summary")) select("c" + i); }}, [
      el("div", {cls: "head"}, [
        el("b", {text: "#" + (c.rank !== undefined ? c.rank : i + 1)}),
        c.chosen ? chip("chosen", "chosen", "the plan the round executed") : null,
        Array.isArray(c.stages) && c.stages.length ? el("span", {cls: "muted",
          text: "joined one block at a time (blocks " + c.stages.join(", ") + ")"}) : null,
        c.verified === true ? chip("verified", "ok", TIPS.verified) : c.verified === false
          ? chip("not verified", "bad", TIPS.verified)
          : chip("not tried", "none", "Level 1 verifies its plans in rank order and stops at the first that verifies"),
        el("span", {}, [tip("count", TIPS.count), " " + (c.count !== undefined ? c.count : "--")]),
        el("span", {}, [tip("p", TIPS.probability), " " + num(c.probability, 3)]),
        el("span", {}, [tip("error", TIPS.error), " " + cm(c.error_m)]),
      ]),
      el("ol", {}, (c.actions || []).map(function (a, k) {
        const v = kin[k] && kin[k].verdict;
        return el("li", {}, [el("span", {title: ACTION_TIP, text: actionText(a) + " "}),
          v === undefined || v === null || v === "unchecked" ? chip("not checked", "none", TIPS.kinematics)
            : chip(String(v), v === "ok" ? "ok" : "bad", TIPS.kinematics)]);
      })),
      facts.length ? el("details", {}, [el("summary", {text: "its symbolic states (" + facts.length + ")"}),
        el("div", {}, facts.map(function (f, k) {
          return el("div", {}, [el("b", {text: k === 0 ? "start: " : "after " + k + ": "}), factList(f)]);
        }))]) : null,
    ]);
  })));
  return box;
}
function level2Panel(r) {
  const l2 = r.level2;
  const box = el("section", {cls: "card", id: "level2"}, [el("h2", {text: "Level 2: the continuous search's tree"})]);
  if (!l2) { box.appendChild(el("p", {cls: "empty", text: "Level 2 did not run in this round."})); return box; }
  box.appendChild(el("div", {cls: "kv muted"}, [
    el("span", {title: l2.reason || null, text: "status: " + (l2.reason || l2.status || "--")}),
    el("span", {text: "expanded: " + (l2.expanded !== undefined ? l2.expanded : tree.T)}),
    el("span", {text: "generated: " + (l2.generated !== undefined ? l2.generated : tree.byId.size)}),
    l2.truncated ? chip("record truncated" + (l2.omitted ? ": " + l2.omitted + " nodes left out" : ""), "warn",
                        "the record keeps only part of a larger search") : null,
    l2.searches > 1 ? el("span", {text: "searches: " + l2.searches}) : null,
    el("span", {text: tree.pathName + ": " + tree.path.size + " node(s)"}),
  ]));
  const filter = el("select", {id: "filter", title: "which nodes the tree shows", onchange: function () {
    S.filter = this.value; applyFilter(); if (S.filter === "all") expanded = defaultExpanded(); renderTree(); writeHash(); }});
  const options = [["all", "all nodes"], ["path", "only " + tree.pathName], ["rejected", "only the rejected successors"]];
  for (const [reason, count] of tree.reasons) options.push(["reason:" + reason, "rejected for: " + reason + " (" + count + ")"]);
  for (const [v, label] of options) filter.appendChild(el("option", {value: v, selected: v === S.filter, text: label}));
  const slider = el("input", {type: "range", id: "timeline", min: 0, max: tree.T, value: S.t === null ? tree.T : S.t,
                              title: "replay the search: the tree as it stood after the first k expansions",
                              oninput: function () { setTimeline(parseInt(this.value, 10)); }});
  box.appendChild(el("div", {cls: "controls"}, [el("label", {}, ["show ", filter]),
    el("button", {id: "expand-all", text: "expand all", onclick: function () {
      for (const n of tree.byId.values()) if (tree.kids.get(n.id).length) expanded.add(n.id); renderTree(); }}),
    el("button", {id: "collapse-all", text: "collapse all", onclick: function () { expanded = new Set(); renderTree(); }}),
    el("span", {id: "tree-count", cls: "muted"})]));
  box.appendChild(el("div", {cls: "controls"}, [tip("timeline", "replays the expansion order"), slider,
    el("button", {id: "play", text: "\u25b6 replay", onclick: function () { play(this); }}),
    el("span", {id: "timeline-label", cls: "muted"})]));
  box.appendChild(el("div", {cls: "muted"}, ["each row: node id, ", tip("exp k", TIPS.order), ", the action into it, ",
    tip("g", TIPS.g), " and ", tip("h", TIPS.h), ", and the kinematic verdict of its edge (hover a rejected one for " +
    "the reason)"]));
  const list = el("div", {cls: "tree", id: "tree", role: "tree"});
  list.addEventListener("click", onTreeClick);
  box.appendChild(list);
  return box;
}
function defaultExpanded() {   // the roots and the path found open, the rest collapsed
  const open = new Set(tree.roots.map(function (n) { return n.id; }));
  for (const id of tree.path) if (tree.byId.has(id)) open.add(id);
  return open;
}
function refinementPanel(r) {
  const box = el("section", {cls: "card", id: "refinement"}, [el("h2", {text: "Refinement into motion"})]);
  const list = Array.isArray(r.refinements) ? r.refinements : [];
  if (!list.length) box.appendChild(el("p", {cls: "empty", text: "no refinement was recorded in this round."}));
  const executedBefore = ROUNDS.slice(0, S.round).filter(function (x) { return x.executed; }).length;
  const closedLoop = ROUNDS.some(function (x) { return x.executed; });
  let last = -1;   // the chosen plan's refinement: the last one of the round's plan
  list.forEach(function (f, i) { if (r.plan && f.plan && sameAction(r.plan, f.plan)) last = i; });
  list.forEach(function (f, i) {
    const chosen = i === last;
    const failed = typeof f.failed_action === "number" ? "; action " + (f.failed_action + 1) + " failed" : "";
    box.appendChild(el("h3", {}, [(i + 1) + ". Level " + (f.level || "?") + " plan of " + (f.plan || []).length +
      " action(s): " + (f.outcome || "--") + failed + " ", chosen ? chip("chosen", "chosen", "the plan this round executed")
      : null]));
    const rows = (f.actions || []).map(function (a, k) {
      const step = closedLoop ? (k === 0 && r.executed && sameAction(r.executed.action, (f.plan || [])[0])
                                 ? executedBefore + 1 : null) : k + 1;
      const link = DATA.replay && chosen && step !== null && !a.failure
        ? el("a", {href: DATA.replay + "#step=" + step, title: "open the Meshcat replay paused at step " + step,
                   text: "replay step " + step}) : null;
      return el("tr", {cls: a.failure ? "failed" : null}, [
        el("td", {cls: "num", text: String(k + 1)}), el("td", {text: actionText((f.plan || [])[k])}),
        el("td", {text: a.ik_branch !== undefined && a.ik_branch !== null ? String(a.ik_branch) : "--"}),
        el("td", {title: a.planner || null, text: motions(a.planner)}), el("td", {cls: "num", text: num(a.time_s, 2)}),
        el("td", {text: a.failure || ""}), el("td", {}, [link])]);
    });
    box.appendChild(el("table", {}, [el("thead", {}, [el("tr", {}, [el("th", {cls: "num", text: "#"}),
      el("th", {text: "action"}), el("th", {}, [tip("IK branch", TIPS.ik)]), el("th", {}, [tip("planner", TIPS.planner)]),
      el("th", {cls: "num", text: "time (s)"}), el("th", {text: "failure"}), el("th", {text: DATA.replay ? "replay" : ""})])]),
      el("tbody", {}, rows)]));
  });
  return box;
}
function defaultSelection(r) {
  const cands = (r.level1 && r.level1.candidates) || [];
  const chosen = cands.findIndex(function (c) { return c.chosen; });
  if (chosen >= 0) return "c" + chosen;
  if (tree && tree.path.size) return "n" + Array.from(tree.path).pop();
  if (r.executed) return "x";
  return null;
}
function renderRound() {
  const r = ROUNDS[S.round];
  tree = r.level2 ? buildTree(r.level2) : null;
  if (tree) {
    expanded = S.expandAll ? new Set(Array.from(tree.kids.keys()).filter(function (id) { return tree.kids.get(id).length; }))
      : defaultExpanded();
    const known = S.filter === "path" || S.filter === "rejected" ||
      (S.filter.indexOf("reason:") === 0 && tree.reasons.has(S.filter.slice(7)));
    if (!known) S.filter = "all";
    if (S.filter !== "all") applyFilter(); else shown = null;
  }
  if (!S.select) S.select = defaultSelection(r);
  const app = document.getElementById("app");
  app.replaceChildren(header(), tabs(), roundSummary(r), el("main", {}, [
    el("div", {}, [level1Panel(r), level2Panel(r)]),
    el("div", {}, [el("section", {cls: "card", id: "scene"}), refinementPanel(r)])]));
  if (tree) {
    if (S.t !== null && S.t < tree.T) setTimeline(S.t); else renderTree();
  }
  renderScene();
  writeHash();
}

readHash();
if (!ROUNDS.length) {
  document.getElementById("app").replaceChildren(header(),
    el("p", {cls: "empty", style: "padding:16px", text: "The record holds no round: the planner was not called."}));
} else renderRound();
document.body.setAttribute("data-ready", "1");
window.tampSearchView = {renderMs: performance.now()};
requestAnimationFrame(function () { setTimeout(function () { window.tampSearchView.paintedMs = performance.now(); }, 0); });
})();
