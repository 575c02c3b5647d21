// The side panel's vehicle and order lists. Rows are created once and then only their changed
// cells are written.

import { age, h, setText } from "./dom.js";

export class VehicleList {
  constructor(tbody, onSelect) {
    this.tbody = tbody;
    this.rows = new Map();
    tbody.addEventListener("click", (event) => {
      const row = event.target.closest("tr[data-row-vehicle]");
      if (row) onSelect(row.getAttribute("data-row-vehicle"));
    });
  }

  rebuild(ids) {
    this.tbody.replaceChildren();
    this.rows.clear();
    for (const id of [...ids].sort()) this.row(id);
  }

  remove(id) {
    const row = this.rows.get(id);
    if (!row) return;
    row.tr.remove();
    this.rows.delete(id);
  }

  row(id) {
    let row = this.rows.get(id);
    if (!row) {
      const chip = h("span", { class: "chip" });
      const cells = [h("td"), h("td", {}, chip), h("td"), h("td", { class: "order" })];
      row = { tr: h("tr", { "data-row-vehicle": id }, ...cells), cells, chip, status: "" };
      this.tbody.append(row.tr);
      this.rows.set(id, row);
    }
    return row;
  }

  paint(vehicle, status, selected) {
    const row = this.row(vehicle.id);
    row.tr.classList.toggle("selected", selected);
    setText(row.cells[0], vehicle.serialNumber);
    if (row.status !== status) {
      row.status = status;
      row.chip.setAttribute("data-status", status);
      row.chip.textContent = status;
    }
    setText(row.cells[2], vehicle.battery === undefined ? "–" : `${Math.round(vehicle.battery)}%`);
    setText(row.cells[3], vehicle.activeOrderId || "");
  }
}

// A waiting (QUEUED) order's row carries two buttons: one puts it first in the queue (a
// priority above every other waiting order's), one cancels it. No vehicle was sent anything
// yet, so nothing else on the page would reach it.
export function paintOrders(tbody, orders, nowMs, onSelectVehicle, queueActions) {
  const waiting = [...orders.values()].filter((order) => order.status === "QUEUED");
  const top = Math.max(0, ...waiting.map((order) => order.priority || 0));
  const next = waiting.reduce((best, order) => (best === null ||
    (order.priority || 0) > (best.priority || 0) ||
    ((order.priority || 0) === (best.priority || 0) && order.createdAt < best.createdAt)
    ? order : best), null);  // the queue's order of service: priority, then first come
  const rows = [...orders.values()].reverse().map((order) => {
    // null: a queued order that any vehicle may take
    const vehicle = order.vehicle ? order.vehicle.split("/").slice(1).join("/") : "any";
    const actions = h("td", { class: "row-actions" });
    if (order.status === "QUEUED") {
      const first = rowButton("first-queued", `put ${order.orderId} first in the queue`, "↑",
        () => queueActions.first(order.orderId, top + 1));
      first.disabled = order === next;
      actions.append(first, rowButton("cancel-queued", `cancel ${order.orderId}`, "✕",
        () => queueActions.cancel(order.orderId)));
    }
    const tr = h("tr", { "data-order-id": order.orderId, "data-status": order.status,
      title: order.reason || "" },
      h("td", { class: "order" }, order.orderId), h("td", {}, vehicle),
      h("td", { class: "order-status" }, order.status, expectedText(order.expectedFinishAt)),
      h("td", { "data-created": order.createdAt },
        age(order.createdAt, nowMs)), actions);
    if (order.vehicle) tr.addEventListener("click", () => onSelectVehicle(order.vehicle));
    return tr;
  });
  tbody.replaceChildren(...rows);
}

// expectedFinishAt (an order under way): when master control expects it done, local time.
function expectedText(at) {
  if (!at) return "";
  const time = new Date(at).toLocaleTimeString([], { hour: "2-digit", minute: "2-digit" });
  return h("span", { class: "expected", title: `expected done ${new Date(at).toLocaleString()}` },
    ` → ${time}`);
}

function rowButton(action, label, text, onClick) {
  const button = h("button", { type: "button", "data-action": action, title: label,
    "aria-label": label }, text);
  button.addEventListener("click", (event) => {
    event.stopPropagation();
    onClick();
  });
  return button;
}

export function refreshAges(tbody, nowMs) {
  for (const cell of tbody.querySelectorAll("td[data-created]")) {
    setText(cell, age(cell.getAttribute("data-created"), nowMs));
  }
}

// The alarm list: what is wrong with the fleet now (GET /alarms' entries, which each vehicle's
// payload carries), worst first, then oldest first; a row selects its vehicle. Rebuilt only when
// the alarms changed, else only their ages move on.
const ALARM_RANK = { FATAL: 0, CONNECTIONBROKEN: 1, SAFETY: 2, CRITICAL: 3, URGENT: 4, WARNING: 5 };

function alarmLevel(alarm) {
  if (alarm.kind === "error") return alarm.error.errorLevel;
  if (alarm.kind === "safety") return "SAFETY";
  return alarm.connection.connectionState;
}

function alarmText(alarm) {
  if (alarm.kind === "error") {
    const e = alarm.error;
    return `${e.errorType} (${e.errorLevel})${e.errorDescription ? `: ${e.errorDescription}` : ""}`;
  }
  if (alarm.kind === "safety") {
    const s = alarm.safety;
    return s.eStop !== "NONE" ? `emergency stop (${s.eStop})` : "protective field violated";
  }
  return "connection broken";
}

export class AlarmList {
  constructor(tbody, counter, onSelect) {
    this.tbody = tbody;
    this.counter = counter;
    this.shown = null;
    tbody.addEventListener("click", (event) => {
      const row = event.target.closest("tr[data-alarm-vehicle]");
      if (row) onSelect(row.getAttribute("data-alarm-vehicle"));
    });
  }

  paint(vehicles, nowMs) {
    const alarms = [];
    for (const vehicle of vehicles) {
      for (const alarm of vehicle.alarms || []) alarms.push({ vehicle, alarm, level: alarmLevel(alarm) });
    }
    const rank = (level) => ALARM_RANK[level] ?? Object.keys(ALARM_RANK).length;
    alarms.sort((a, b) => rank(a.level) - rank(b.level) || a.alarm.since.localeCompare(b.alarm.since));
    const key = JSON.stringify(alarms.map(({ vehicle, alarm }) => [vehicle.id, alarm]));
    if (key === this.shown) {
      refreshAges(this.tbody, nowMs);
      return;
    }
    this.shown = key;
    const rows = alarms.map(({ vehicle, alarm, level }) => h("tr",
      { "data-alarm-vehicle": vehicle.id, "data-level": level },
      h("td", {}, vehicle.serialNumber), h("td", { class: "alarm" }, alarmText(alarm)),
      h("td", { "data-created": alarm.since, title: `since ${new Date(alarm.since).toLocaleString()}` },
        age(alarm.since, nowMs))));
    this.tbody.replaceChildren(...(rows.length ? rows
      : [h("tr", { class: "none" }, h("td", { colspan: "3" }, "none"))]));
    setText(this.counter, alarms.length ? `(${alarms.length})` : "");
  }
}
