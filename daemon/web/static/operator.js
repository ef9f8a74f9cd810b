// The operator's controls on the live page (docs/console.md, "Operator actions"): with an
// operator session, a form that starts a cycle (VIN, car model, keep the capture) and a
// button that cancels the running one, through POST /api/cycles and /api/cycles/ID/cancel.
// Every POST carries the X-Linecal-Action header that the daemon requires of write actions
// (a page of another site cannot send it). A read-only session sees, when the daemon has an
// operator token, a link to log in as operator instead.
"use strict";

(function () {
  function element(tag, attributes, content) {
    const e = document.createElement(tag);
    for (const [key, value] of Object.entries(attributes || {})) e.setAttribute(key, value);
    if (content) e.textContent = content;
    return e;
  }

  async function post(path, body) {
    const response = await fetch(path, {
      method: "POST",
      credentials: "same-origin",
      headers: { "Content-Type": "application/json", "X-Linecal-Action": "1" },
      body: JSON.stringify(body || {}),
    });
    const answer = await response.json();
    if (!response.ok) throw new Error(answer.error || response.statusText);
    return answer;
  }

  // The cycle the live page shows, while it runs; "" else.
  function runningCycle() {
    const body = document.body.dataset;
    return body.cycle && body.ended !== body.cycle ? body.cycle : "";
  }

  function panel(models) {
    const form = element("form", { id: "operator", class: "operator" });
    const vin = element("input", { id: "op-vin", name: "vin", maxlength: "17", size: "19",
                                   placeholder: "VIN", autocomplete: "off", required: "" });
    const model = element("select", { id: "op-model", name: "car_model_id" });
    for (const id of models) model.appendChild(element("option", { value: id }, id));
    const record = element("input", { id: "op-record", type: "checkbox" });
    const keep = element("label", {}, " keep the capture");
    keep.prepend(record);
    const start = element("button", { id: "op-start", type: "submit" }, "Start cycle");
    const cancel = element("button", { id: "op-cancel", type: "button" }, "Cancel cycle");
    const message = element("span", { id: "op-message", class: "message" });
    form.append(vin, model, keep, start, cancel, message);

    const update = () => {
      const running = runningCycle();
      start.disabled = running !== "";
      cancel.disabled = running === "";
    };
    new MutationObserver(update).observe(document.body, {
      attributes: true, attributeFilter: ["data-cycle", "data-ended"],
    });
    update();

    form.addEventListener("submit", async (event) => {
      event.preventDefault();
      message.textContent = "";
      start.disabled = true;
      try {
        const answer = await post("/api/cycles", {
          vin: vin.value.trim().toUpperCase(),
          car_model_id: model.value,
          record_capture: record.checked,
        });
        form.dataset.started = answer.cycle_id;
      } catch (error) {
        message.textContent = error.message;
      }
      update();
    });
    cancel.addEventListener("click", async () => {
      const id = runningCycle();
      if (!id) return;
      message.textContent = "";
      try {
        await post("/api/cycles/" + encodeURIComponent(id) + "/cancel");
      } catch (error) {
        message.textContent = error.message;
      }
    });
    return form;
  }

  async function init() {
    const session = await (await fetch("/api/session", { credentials: "same-origin" })).json();
    if (session.role !== "operator") {
      // The link's place is kept in the header (index.html) so that the others do not move.
      if (session.operator_login) document.getElementById("operator-login").hidden = false;
      return;
    }
    const status = await (await fetch("/api/status", { credentials: "same-origin" })).json();
    document.querySelector("main .car").after(panel(status.car_models));
    document.body.dataset.role = "operator";
  }

  document.addEventListener("DOMContentLoaded", () => {
    if (document.body.dataset.page === "live") init().catch(() => {});
  });
})();
