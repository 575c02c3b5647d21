// The selected vehicle's panel: facts, the buttons that act on it, its traffic situation,
// errors and action states. Built once; updates only write text and rebuild the short lists.

import { h, setText } from "./dom.js";
import { STATUS_LABELS } from "./status.js";

const FIELDS = [
  ["connection", "connection"], ["service", "service"], ["operatingMode", "mode"], ["battery", "battery"],
  ["loads", "loads"], ["loadTypes", "takes"], ["maps", "maps"], ["position", "position"],
  ["lastNodeId", "last node"], ["order", "order"],
];

// state.loads as a line: "none", "L1 (EPAL) on front, a load", or "not reported" (§6.10.6).
function describeLoads(loads) {
  if (!loads) return "not reported";
  if (loads.length === 0) return "none";
  return loads.map((load) => {
    const type = load.loadType ? ` (${load.loadType})` : "";
    const where = load.loadPosition ? ` on ${load.loadPosition}` : "";
    return `${load.loadId || "a load"}${type}${where}`;
  }).join(", ");
}

export class Details {
  constructor(section, actions) {
    this.section = section;
    this.name = h("span", { class: "name" });
    this.chip = h("span", { class: "chip" });
    this.fields = {};
    const list = h("dl");
    for (const [key, label] of FIELDS) {
      this.fields[key] = h("dd", { "data-field": key });
      list.append(h("dt", {}, label), this.fields[key]);
    }
    this.buttons = {
      cancel: h("button", { type: "button", "data-action": "cancel" }, "Cancel order"),
      pause: h("button", { type: "button", "data-action": "pause" }, "Pause"),
      resume: h("button", { type: "button", "data-action": "resume" }, "Resume"),
      close: h("button", { type: "button", "data-action": "close", title: "deselect" }, "×"),
      sendToType: h("button", { type: "button", "data-action": "sendToType" }, "Send"),
      service: h("button", { type: "button", "data-action": "service" }, "Take out of service"),
    };
    this.serviceNote = h("input", { type: "text", "data-field": "service-note", maxlength: "500",
      placeholder: "why (optional)", title: "why it is taken out of service" });
    this.stationType = h("select", { "data-field": "station-type", title: "station type" });
    this.sendToType = h("div", { class: "actions", hidden: "" },
      "to the nearest ", this.stationType, " ", this.buttons.sendToType);
    for (const [name, button] of Object.entries(this.buttons)) {
      button.addEventListener("click", () => actions[name]());
    }
    this.traffic = h("div", { class: "traffic" });
    this.errors = h("ul", { class: "errors" });
    this.actionStates = h("ul", { class: "action-states" });
    section.replaceChildren(
      h("h2", {}, h("span", {}, this.name, " ", this.chip), this.buttons.close), list,
      h("div", { class: "actions" }, this.buttons.cancel, this.buttons.pause, this.buttons.resume),
      h("div", { class: "actions" }, this.buttons.service, " ", this.serviceNote),
      h("p", { class: "hint" }, "Click a node on the map to send this vehicle there."),
      this.sendToType,
      h("h2", {}, "Traffic"), this.traffic, h("h2", {}, "Errors"), this.errors,
      h("h2", {}, "Action states"), this.actionStates,
    );
    this.onSelectVehicle = actions.select;
  }

  // The graph's station types, offered as "to the nearest <type>" (POST /orders stationType).
  setStationTypes(types) {
    const chosen = this.stationType.value;
    this.stationType.replaceChildren(...types.map((t) => h("option", { value: t }, t)));
    if (types.includes(chosen)) this.stationType.value = chosen;
    this.sendToType.hidden = types.length === 0;
  }

  chosenStationType() {
    return this.stationType.value;
  }

  // The note typed for taking the vehicle out of service (cleared once used).
  takeServiceNote() {
    const note = this.serviceNote.value.trim();
    this.serviceNote.value = "";
    return note;
  }

  show(vehicle, status, traffic, trafficActive) {
    this.section.hidden = !vehicle;
    if (!vehicle) return;
    this.section.setAttribute("data-vehicle-selected", vehicle.id);
    setText(this.name, vehicle.serialNumber);
    this.chip.setAttribute("data-status", status);
    setText(this.chip, STATUS_LABELS[status]);
    const f = this.fields;
    setText(f.connection, vehicle.connection || "never seen");
    const outOfService = vehicle.inService === false;
    setText(f.service, outOfService ? `out of service since ${vehicle.outOfServiceSince}` +
      `${vehicle.outOfServiceNote ? `: ${vehicle.outOfServiceNote}` : ""}` : "in service");
    setText(this.buttons.service, outOfService ? "Put back in service" : "Take out of service");
    this.serviceNote.hidden = outOfService;
    setText(f.operatingMode, vehicle.reportedOperatingMode || vehicle.operatingMode || "–");
    setText(f.battery, vehicle.battery === undefined ? "–" :
      `${vehicle.battery.toFixed(1)} %${vehicle.charging ? " (charging)" : ""}`);
    setText(f.loads, vehicle.hasState ? describeLoads(vehicle.loads) : "–");
    // the factsheet's load sets: what a pick or drop naming a loadType may send it
    setText(f.loadTypes, vehicle.loadTypes ? vehicle.loadTypes.join(", ") : "any load type");
    // state.maps (2.1, 3.0): orders go to it only on a map it has ENABLED
    setText(f.maps, vehicle.maps && vehicle.maps.length ? vehicle.maps.map((m) =>
      `${m.mapId} ${m.mapVersion} (${m.mapStatus.toLowerCase()})`).join(", ") : "none listed");
    setText(f.position, vehicle.x === null ? "unknown" :
      `x ${vehicle.x.toFixed(2)}, y ${vehicle.y.toFixed(2)}, θ ${(vehicle.theta || 0).toFixed(2)}`);
    setText(f.lastNodeId, vehicle.lastNodeId || "–");
    // expectedFinishAt: master control's estimate, in the page's local time
    const expected = vehicle.activeOrderExpectedFinishAt
      ? `, expected ${new Date(vehicle.activeOrderExpectedFinishAt).toLocaleTimeString()}` : "";
    setText(f.order, vehicle.activeOrderId
      ? `${vehicle.activeOrderId} ${vehicle.activeOrderStatus || ""}${expected}`
      : vehicle.orderId || "none");
    this.buttons.cancel.disabled = !vehicle.activeOrderId;
    this.buttons.pause.disabled = Boolean(vehicle.paused);
    this.buttons.resume.disabled = !vehicle.paused;
    this.showTraffic(traffic, trafficActive);
    this.showErrors(vehicle.errors || []);
    this.showActions(vehicle.actionStates || []);
  }

  showTraffic(traffic, active) {
    if (!active) {
      this.traffic.replaceChildren(h("p", { class: "hint" }, "traffic control is not active"));
      return;
    }
    if (!traffic) {
      this.traffic.replaceChildren(h("p", { class: "hint" }, "no reservations"));
      return;
    }
    const waits = (traffic.waitingFor || []).map((id) => {
      const link = h("a", { "data-select": id }, id);
      link.addEventListener("click", () => this.onSelectVehicle(id));
      return h("li", {}, link);
    });
    const waited = traffic.waitedS === null || traffic.waitedS === undefined ? "" :
      ` for ${traffic.waitedS.toFixed(1)} s`;
    this.traffic.replaceChildren(
      h("dl", {},
        h("dt", {}, "holds"), h("dd", { "data-field": "holds" }, (traffic.holds || []).join(", ") || "–"),
        h("dt", {}, "waits at"), h("dd", {}, traffic.waitingAt ? `${traffic.waitingAt}${waited}` : "–"),
        h("dt", {}, "conflict"), h("dd", {}, traffic.conflict || "–")),
      waits.length ? h("div", {}, "waits for:", h("ul", { "data-field": "waiting-for" }, ...waits)) : "",
    );
  }

  showErrors(errors) {
    const items = errors.map((e) => h("li", { class: e.errorLevel },
      `${e.errorType} (${e.errorLevel})${e.errorDescription ? `: ${e.errorDescription}` : ""}`));
    this.errors.replaceChildren(...(items.length ? items : [h("li", { class: "none" }, "none")]));
  }

  showActions(actionStates) {
    const items = actionStates.slice(-12).map((a) => h("li", { class: a.actionStatus },
      `${a.actionType || "action"} ${a.actionId}: ${a.actionStatus}` +
      `${a.resultDescription ? ` – ${a.resultDescription}` : ""}`));
    this.actionStates.replaceChildren(...(items.length ? items : [h("li", { class: "none" }, "none")]));
  }
}
