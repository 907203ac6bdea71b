// zwidth dashboard: the API token (entered once, kept in this browser's
// local storage), the action buttons and the rig window form. Reads need no
// token; every action calls the JSON API with it. No inline script, no eval.
(function () {
  "use strict";
  var KEY = "zwidth-token";
  function token() { try { return localStorage.getItem(KEY) || ""; } catch (e) { return ""; } }
  function showToken() {
    var s = document.getElementById("token-state");
    if (s) s.textContent = token() ? "token saved" : "no token: actions are refused";
  }
  function flash(text, ok) {
    var f = document.getElementById("flash");
    if (!f) return;
    f.textContent = text;
    f.className = ok ? "ok" : "bad";
    if (ok) setTimeout(function () { if (f.textContent === text) { f.textContent = ""; f.className = ""; } }, 4000);
  }
  function refresh() {
    var live = document.getElementById("live");
    if (live && window.htmx) {
      var url = (live.getAttribute("hx-get") || "").split("?")[0];
      if (url) window.htmx.ajax("GET", url, { target: "#live", swap: "outerHTML" });
    }
  }
  function call(method, url, body) {
    var headers = { "Accept": "application/json" };
    var t = token();
    if (t) headers["Authorization"] = "Bearer " + t;
    if (body !== undefined) headers["Content-Type"] = "application/json";
    return fetch(url, { method: method, headers: headers, body: body === undefined ? undefined : JSON.stringify(body), credentials: "same-origin" })
      .then(function (r) {
        if (r.ok) { flash(method + " " + url + ": done", true); refresh(); return; }
        return r.json().catch(function () { return {}; }).then(function (p) {
          var why = p.detail || p.title || ("HTTP " + r.status);
          if (r.status === 401 || r.status === 403) why += " (enter the API token at the top: it is in the file <db>.token next to the database)";
          flash(why, false);
        });
      })
      .catch(function (e) { flash("the server did not answer: " + e, false); });
  }
  document.addEventListener("DOMContentLoaded", function () {
    showToken();
    var form = document.getElementById("token-form");
    if (form) form.addEventListener("submit", function (ev) {
      ev.preventDefault();
      var v = document.getElementById("token").value.trim();
      try { if (v) localStorage.setItem(KEY, v); } catch (e) { flash("this browser keeps no local storage", false); }
      document.getElementById("token").value = "";
      showToken();
    });
    var forget = document.getElementById("token-forget");
    if (forget) forget.addEventListener("click", function () {
      try { localStorage.removeItem(KEY); } catch (e) { /* nothing kept */ }
      showToken();
    });
  });
  document.addEventListener("click", function (ev) {
    var b = ev.target.closest ? ev.target.closest("button.action") : null;
    if (!b) return;
    ev.preventDefault();
    call(b.getAttribute("data-method"), b.getAttribute("data-url"));
  });
  document.addEventListener("submit", function (ev) {
    var f = ev.target;
    if (!f.classList || !f.classList.contains("window")) return;
    ev.preventDefault();
    var rig = f.getAttribute("data-rig");
    call("PUT", "/v1/rigs/" + encodeURIComponent(rig) + "/window", {
      start: f.elements.start.value, end: f.elements.end.value, tz: f.elements.tz.value || "UTC"
    });
  });
})();
