// Operator page of locem_bridge: renders /api/state (pushed by Server-Sent Events, polled when the stream is
// down) and sends the operator's actions as JSON POSTs. Plain JS, no external resources.
"use strict";
(function () {
  var $ = function (id) { return document.getElementById(id); };
  var lastParts = {};          // section -> JSON text last rendered (render only what changed)
  var wallImgs = {};           // wall id -> {fig, img, version}
  var pollTimer = null;
  var POSITIVE = ["valid", "done", "yes", "ok", "mounted", "success", "SUCCESS"];
  var NEGATIVE = ["invalid", "no", "reject", "failure", "FAILURE"];

  function el(tag, attrs, text) {
    var e = document.createElement(tag);
    Object.keys(attrs || {}).forEach(function (k) {
      if (k === "class") e.className = attrs[k]; else e.setAttribute(k, attrs[k]);
    });
    if (text !== undefined && text !== null) e.textContent = String(text);
    return e;
  }
  function setText(id, text) { var e = $(id); var t = (text === "" || text == null) ? "–" : String(text);
    if (e.textContent !== t) e.textContent = t; }
  function localName(v) {
    if (typeof v !== "string") return v;
    var m = /^[a-z][a-z0-9+.-]*:\/\/\S*[#\/]([^#\/]+)$/i.exec(v);
    return m ? m[1] : v;
  }

  // ---------------------------------------------------------------- errors
  // the server logs every refusal in the event log itself; the banner shows the latest one until dismissed
  function showError(message) {
    $("error-text").textContent = message;
    $("error-banner").hidden = false;
  }
  function hideError() { $("error-banner").hidden = true; }
  $("error-close").addEventListener("click", hideError);

  // ---------------------------------------------------------------- actions
  function post(url, body) {
    return fetch(url, {method: "POST", headers: {"Content-Type": "application/json"},
                       body: JSON.stringify(body || {})})
      .then(function (r) {
        return r.text().then(function (t) {
          var data = null;
          try { data = t ? JSON.parse(t) : {}; } catch (e) { data = null; }
          if (!r.ok) {
            var msg = (data && data.error && data.error.message) || ("HTTP " + r.status + " " + r.statusText);
            throw new Error(msg);
          }
          hideError();
          return data;
        });
      })
      .catch(function (err) { showError(err.message || String(err)); throw err; });
  }
  $("stop-button").addEventListener("click", function () {
    post("/api/stop", {}).then(refreshNow, function () {});
  });

  // Pause / Resume / Abort / Reset: the skill methods of HICEM's running action (Suspend, Resume, Halt, Reset),
  // each enabled only while the action's skill state allows it (snapshot.allowed)
  var SKILL_BUTTONS = ["skill-suspend", "skill-resume", "skill-halt", "skill-reset"];
  var skillBusy = false;        // a method sent and not answered yet: every button waits
  var lastSnapshot = null;
  function renderSkillButtons(s) {
    var allowed = (s && s.allowed) || [];
    SKILL_BUTTONS.forEach(function (id) {
      var b = $(id);
      var on = !skillBusy && allowed.indexOf(b.getAttribute("data-method")) >= 0;
      if (b.disabled === on) b.disabled = !on;
    });
  }
  SKILL_BUTTONS.forEach(function (id) {
    var b = $(id);
    b.addEventListener("click", function () {
      skillBusy = true;
      renderSkillButtons(lastSnapshot);
      post("/api/skill/" + b.getAttribute("data-method").toLowerCase(), {})
        .then(function () { skillBusy = false; renderSkillButtons(lastSnapshot); return refreshNow(); },
              function () { skillBusy = false; renderSkillButtons(lastSnapshot); });
    });
  });

  // ---------------------------------------------------------------- rendering
  function changed(part, value) {
    var t = JSON.stringify(value);
    if (lastParts[part] === t) return false;
    lastParts[part] = t;
    return true;
  }

  function renderStatus(s) {
    lastSnapshot = s;
    renderSkillButtons(s);
    if (!changed("status", s)) return;
    setText("status-process", localName(s.process));
    var phase = $("status-phase");
    phase.textContent = s.phase || "idle";
    phase.className = "phase phase-" + (s.phase || "idle");
    setText("status-action", s.action);
    setText("status-skill", s.skill);
    setText("status-tree", s.tree);
    setText("status-node", s.node);
    var ss = $("status-skill-state");
    ss.textContent = s.skill_state || "–";
    ss.className = "skill-state" + (s.skill_state ? " skill-" + s.skill_state.toLowerCase() : "");
    $("status-skill-detail").textContent = s.skill_detail || "";
    setText("status-detail", s.detail);
    var h = s.health || {status: "unknown", detail: ""};
    [$("status-health"), $("header-health")].forEach(function (b, i) {
      b.className = "badge health-" + h.status;
      b.textContent = (i ? "health: " : "") + h.status;
    });
    $("status-health-detail").textContent = h.detail || "";
    var p = s.progress;
    if (p && p.total > 0) {
      $("progress-bar").style.width = Math.max(0, Math.min(100, 100 * p.done / p.total)).toFixed(1) + "%";
      setText("progress-text", p.text || (p.done + " of " + p.total));
    } else {
      $("progress-bar").style.width = "0%";
      setText("progress-text", p && p.text ? p.text : "");
    }
  }

  var promptBoxes = {};         // prompt id -> its box (kept while the prompt stays open: no flicker)
  function renderPrompts(prompts) {
    if (!changed("prompts", prompts)) return;
    var list = $("prompt-list");
    var count = $("prompt-count");
    count.textContent = String(prompts.length);
    count.className = "count" + (prompts.length ? " has" : "");
    var open = {};
    prompts.forEach(function (p) { open[p.id] = true; });
    Object.keys(promptBoxes).forEach(function (id) {
      if (!open[id]) { list.removeChild(promptBoxes[id]); delete promptBoxes[id]; }
    });
    var empty = $("no-prompts");
    if (!prompts.length) {
      if (!empty) list.appendChild(el("p", {"class": "muted", "id": "no-prompts"}, "No open prompts."));
      return;
    }
    if (empty) list.removeChild(empty);
    prompts.forEach(function (p) {
      if (promptBoxes[p.id]) return;
      var box = el("div", {"class": "prompt", "data-prompt-id": p.id, "data-kind": p.kind});
      box.appendChild(el("div", {"class": "prompt-kind"}, (p.kind || "question").replace(/_/g, " ")));
      box.appendChild(el("div", {"class": "prompt-text"}, p.text));
      p.choices.forEach(function (c) {
        var cls = POSITIVE.indexOf(c) >= 0 ? "answer-positive" : (NEGATIVE.indexOf(c) >= 0 ? "answer-negative" : "");
        var b = el("button", {"type": "button", "class": cls, "data-answer": c}, c);
        b.addEventListener("click", function () {
          box.querySelectorAll("button").forEach(function (x) { x.disabled = true; });
          post("/api/prompts/" + encodeURIComponent(p.id) + "/reply", {answer: c})
            .then(refreshNow, function () {
              box.querySelectorAll("button").forEach(function (x) { x.disabled = false; });
            });
        });
        box.appendChild(b);
      });
      promptBoxes[p.id] = box;
      list.appendChild(box);
    });
  }

  function renderProcesses(procs) {
    if (!changed("processes", procs)) return;
    var list = $("process-list");
    list.textContent = "";
    if (!procs.length) { list.appendChild(el("li", {"class": "muted"}, "No processes offered.")); return; }
    procs.forEach(function (p) {
      var li = el("li", {"data-iri": p.iri});
      var name = el("span", {"class": "pname", "title": p.description || ""}, p.name || localName(p.iri));
      name.appendChild(el("span", {"class": "piri"}, p.iri));
      li.appendChild(name);
      var b = el("button", {"type": "button", "class": "start-button", "data-iri": p.iri}, "Start");
      b.addEventListener("click", function () {
        b.disabled = true;
        post("/api/processes/start", {iri: p.iri}).then(refreshNow, function () {})
          .then(function () { b.disabled = false; });
      });
      li.appendChild(b);
      var m = el("button", {"type": "button", "class": "match-button", "data-iri": p.iri,
                            "title": "which skill realizes each task of this process"}, "Skills");
      m.addEventListener("click", function () { showMatch(p); });
      li.appendChild(m);
      list.appendChild(li);
    });
  }

  // ---------------------------------------------------------------- skill matching (GET /api/match)
  function kindText(kind, operator) { return " (" + kind + (operator ? ", operator" : "") + ")"; }
  function renderMatch(p, view) {
    var box = $("match-result");
    box.textContent = "";
    $("match-process").textContent = (p.name || localName(p.iri)) + (view.robot_name ? " on " + view.robot_name : "") +
      (view.ok ? "" : " – not every task can be realized");
    var t = el("table", {"class": "match", "id": "match-table", "data-process": p.iri});
    var hr = el("tr");
    ["Task", "Capability", "Chosen skill", "Rejected candidates"].forEach(function (c) { hr.appendChild(el("th", {}, c)); });
    t.appendChild(hr);
    view.tasks.forEach(function (k) {
      var tr = el("tr", {"data-task": k.task, "data-action": k.action_type, "class": k.ok ? "" : "unmatched"});
      var task = el("td", {"title": k.node}, k.action_type || k.task);
      task.appendChild(el("div", {"class": "kind"}, k.task));
      tr.appendChild(task);
      tr.appendChild(el("td", {}, k.capability || "– (its action type's tree)"));
      var chosen = el("td", {"class": "chosen"});
      if (k.chosen) {
        chosen.setAttribute("data-skill", k.chosen.name);
        chosen.setAttribute("data-kind", k.chosen.kind);
        chosen.appendChild(el("span", {"class": "chosen-name"}, k.chosen.name));
        chosen.appendChild(el("span", {"class": "kind"}, kindText(k.chosen.kind, k.chosen.operator)));
        if (k.chosen.steps.length) {
          var ol = el("ol", {"class": "steps"});
          k.chosen.steps.forEach(function (s) {
            ol.appendChild(el("li", {"data-skill": s.name}, s.name + (s.arguments ? " " + s.arguments : "") +
                              kindText(s.kind, s.operator) + (s.capability ? " for " + s.capability : "")));
          });
          chosen.appendChild(ol);
        }
      } else {
        chosen.textContent = k.capability ? "none: " + (k.problem || "no skill realizes " + k.capability) : "–";
      }
      tr.appendChild(chosen);
      var rej = el("td", {"class": "rejected"});
      if (!k.rejected.length) rej.appendChild(el("span", {"class": "muted"}, "none"));
      else {
        var ul = el("ul");
        k.rejected.forEach(function (r) {
          ul.appendChild(el("li", {"data-candidate": r.name}, r.name + " (" + r.kind + "): " + r.reason));
        });
        rej.appendChild(ul);
      }
      tr.appendChild(rej);
      t.appendChild(tr);
    });
    box.appendChild(t);
  }
  function showMatch(p) {
    $("match-process").textContent = (p.name || localName(p.iri)) + " – asking PEMKRE…";
    fetch("/api/match?process=" + encodeURIComponent(p.iri))
      .then(function (r) {
        return r.json().then(function (data) {
          if (!r.ok) throw new Error((data && data.error && data.error.message) || ("HTTP " + r.status));
          hideError();
          renderMatch(p, data.match);
        });
      })
      .catch(function (err) {
        $("match-process").textContent = (p.name || localName(p.iri)) + " – no matching";
        showError(err.message || String(err));
      });
  }

  function renderWalls(walls) {
    if (!changed("walls", walls)) return;
    var box = $("walls");
    if (!walls.length) { box.textContent = ""; box.appendChild(el("p", {"class": "muted"}, "No wall pictures yet."));
      wallImgs = {}; return; }
    var seen = {};
    walls.forEach(function (w) {
      seen[w.id] = true;
      var entry = wallImgs[w.id];
      if (!entry) {
        if (!Object.keys(wallImgs).length) box.textContent = "";
        var fig = el("figure", {"data-wall": w.id});
        var img = el("img", {"alt": "picture of " + w.id, "data-wall": w.id});
        fig.appendChild(img);
        var cap = el("figcaption", {}, w.id);
        fig.appendChild(cap);
        box.appendChild(fig);
        entry = wallImgs[w.id] = {fig: fig, img: img, cap: cap, version: null};
      }
      if (entry.version !== w.version) {
        entry.version = w.version;
        if (w.url) { entry.img.src = w.url; entry.img.hidden = false; entry.cap.textContent = w.id; }
        else { entry.img.hidden = true; entry.cap.textContent = w.id + " (picture not available yet)"; }
        entry.img.setAttribute("data-version", w.version || "");
      }
    });
    Object.keys(wallImgs).forEach(function (id) {
      if (!seen[id]) { box.removeChild(wallImgs[id].fig); delete wallImgs[id]; }
    });
  }

  function fmt(v) {
    if (typeof v === "number") return Number.isInteger(v) ? String(v) : v.toFixed(3).replace(/0+$/, "").replace(/\.$/, "");
    if (v === null || v === undefined) return "";
    if (typeof v === "object") return JSON.stringify(v);
    return String(localName(v));
  }
  function renderKpis(kpis) {
    if (!changed("kpis", kpis)) return;
    var box = $("kpi-tables");
    box.textContent = "";
    var names = Object.keys(kpis || {});
    if (!names.length) { box.appendChild(el("p", {"class": "muted"}, "No KPIs yet (shown when a run has data).")); return; }
    names.forEach(function (name) {
      var rows = kpis[name];
      if (!Array.isArray(rows)) rows = Object.keys(rows || {}).map(function (k) { return {name: k, value: rows[k]}; });
      var cols = [];
      rows.forEach(function (r) { Object.keys(r).forEach(function (k) { if (cols.indexOf(k) < 0) cols.push(k); }); });
      var wrap = el("div", {"class": "kpi-scroll"});
      var t = el("table", {"class": "kpi", "data-kpi": name});
      t.appendChild(el("caption", {}, name.replace(/_/g, " ")));
      var hr = el("tr");
      cols.forEach(function (c) { hr.appendChild(el("th", {}, c)); });
      t.appendChild(hr);
      if (!rows.length) { var er = el("tr"); er.appendChild(el("td", {"colspan": Math.max(1, cols.length)}, "no rows"));
        t.appendChild(er); }
      rows.forEach(function (r) {
        var tr = el("tr");
        cols.forEach(function (c) {
          var v = r[c];
          var td = el("td", {"class": typeof v === "number" ? "num" : ""}, fmt(v));
          if (typeof v === "string" && v !== fmt(v)) td.title = v;
          tr.appendChild(td);
        });
        t.appendChild(tr);
      });
      wrap.appendChild(t);
      box.appendChild(wrap);
    });
  }

  // ---------------------------------------------------------------- planned manual work (doc.manual)
  function metres(v) { return typeof v === "number" ? String(Number(v.toFixed(2))) : "?"; }
  function span(pair) { return pair && pair.length === 2 ? metres(pair[0]) + "–" + metres(pair[1]) + " m" : "–"; }
  function renderManual(items) {
    if (!changed("manual", items)) return;
    var box = $("manual-list");
    var count = $("manual-count");
    count.textContent = String(items.length);
    count.className = "count" + (items.length ? " has" : "");
    box.textContent = "";
    if (!items.length) { box.appendChild(el("p", {"class": "muted", "id": "no-manual"}, "no manual work")); return; }
    var wrap = el("div", {"class": "manual-scroll"});
    var t = el("table", {"class": "manual", "id": "manual-table"});
    var hr = el("tr");
    ["Work", "Area / joint", "Part", "Along", "Height", "Reason"].forEach(function (c) {
      hr.appendChild(el("th", {}, c));
    });
    t.appendChild(hr);
    items.forEach(function (m) {
      var tr = el("tr", {"class": "manual-row", "data-kind": m.kind, "data-work": m.work, "data-feature": m.feature,
                         "data-part": String(m.part), "title": m.text || ""});
      var work = el("td", {"class": "manual-work"});
      work.appendChild(el("span", {"class": "work work-" + m.work}, m.work));
      tr.appendChild(work);
      tr.appendChild(el("td", {"class": "manual-feature"}, m.feature));
      tr.appendChild(el("td", {"class": "manual-part"}, (m.kind === "joint" ? "part " : "section ") + m.part));
      tr.appendChild(el("td", {"class": "manual-along"}, span(m.along)));
      tr.appendChild(el("td", {"class": "manual-height"}, m.height ? span(m.height) : "–"));
      tr.appendChild(el("td", {"class": "manual-reason"}, m.reason || "–"));
      t.appendChild(tr);
    });
    wrap.appendChild(t);
    box.appendChild(wrap);
  }

  function renderEvents(events) {
    if (!changed("events", events)) return;
    var log = $("event-log");
    log.textContent = "";
    (events || []).forEach(function (e) { log.appendChild(el("li", {"class": e.level}, e.time + " " + e.text)); });
    log.scrollTop = log.scrollHeight;
  }

  var shown = {server: null, version: -1};   // the document on screen
  function render(doc) {
    if (!doc || !doc.snapshot) return;
    // documents can arrive out of order (a /api/state answer overtaken by a pushed event): never go back
    if (doc.server_id === shown.server && doc.version <= shown.version) return;
    shown.server = doc.server_id;
    shown.version = doc.version;
    renderStatus(doc.snapshot);
    renderPrompts(doc.prompts || []);
    renderProcesses(doc.processes || []);
    renderWalls(doc.walls || []);
    renderKpis(doc.kpis || {});
    renderManual(doc.manual || []);
    renderEvents(doc.events || []);
    var be = $("backend-error");
    be.hidden = !doc.backend_error;
    be.textContent = doc.backend_error ? "Backend problem: " + doc.backend_error : "";
    document.body.setAttribute("data-version", String(doc.version));
  }

  // ---------------------------------------------------------------- transport
  function refreshNow() {
    return fetch("/api/state").then(function (r) { return r.json(); }).then(render, function () {});
  }
  function setConnected(on) {
    var c = $("connection");
    c.className = "conn " + (on ? "conn-on" : "conn-off");
    c.textContent = on ? "live" : "reconnecting…";
    if (on && pollTimer) { clearInterval(pollTimer); pollTimer = null; }
    if (!on && !pollTimer) pollTimer = setInterval(refreshNow, 2000);
  }
  function connect() {
    if (!window.EventSource) { setConnected(false); return; }
    var es = new EventSource("/api/events");
    es.addEventListener("state", function (e) { setConnected(true); render(JSON.parse(e.data)); });
    es.onopen = function () { setConnected(true); };
    es.onerror = function () { setConnected(false); };
  }
  refreshNow();
  connect();
})();
