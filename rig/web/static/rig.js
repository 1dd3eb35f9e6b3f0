// rig clinic: the page's CSRF token for scripts (a form carries it in its csrftoken field).
// rig.post(url, body) sends JSON with the x-csrftoken header; no inline script anywhere.
(function () {
  "use strict";
  function csrf() {
    var m = document.querySelector('meta[name="csrf-token"]');
    return m ? m.getAttribute("content") : "";
  }
  function post(url, body) {
    return fetch(url, {
      method: "POST", credentials: "same-origin",
      headers: {"Content-Type": "application/json", "x-csrftoken": csrf()},
      body: JSON.stringify(body || {})
    });
  }
  window.rig = Object.assign(window.rig || {}, {csrf: csrf, post: post});
})();
