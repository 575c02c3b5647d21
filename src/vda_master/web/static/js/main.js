// The live map: wires the stream, the store, the map and the side panel together. All DOM work
// happens in frame(), at most once per animation frame, for what changed since the last one.

import {
  addZone, ApiError, apiKey, cancelOrder, fleetInstantAction, instantAction, liftZone, sendTo,
  sendToStationType,
  setApiKey, setInService, setPriority, takeKeyFromUrl,
} from "./api.js";
import { Details } from "./details.js";
import { AlarmList, paintOrders, refreshAges, VehicleList } from "./lists.js";
import { MapView } from "./mapview.js";
import { drawOverlay } from "./overlay.js";
import { Probe } from "./probe.js";
import { vehicleStatus } from "./status.js";
import { Store } from "./store.js";
import { openStream } from "./stream.js";
import { ZoneDraw } from "./zonedraw.js";

const $ = (selector) => document.querySelector(selector);
const store = new Store();
const probe = new Probe();
const statuses = new Map();
const ui = { selected: null, selectionChanged: false, fitted: false, frameRequested: false };

const map = new MapView($("#map-stack"), {
  onNode: sendSelectedTo,
  onVehicle: select,
  onZone: (polygon) => zones.clickZone(polygon),
  onDraw: (x, y) => zones.click(x, y),
  drawing: () => zones.drawing,
});
const vehicleList = new VehicleList($("#vehicle-list tbody"), select);
const alarmList = new AlarmList($("#alarm-list tbody"), $("#alarm-count"), select);
const details = new Details($("#selected"), {
  cancel: () => act((v) => cancelOrder(v.activeOrderId), (v) => `cancel of ${v.activeOrderId} sent`),
  pause: () => act((v) => instantAction(v, "startPause"), (v) => `${v.serialNumber}: startPause sent`),
  resume: () => act((v) => instantAction(v, "stopPause"), (v) => `${v.serialNumber}: stopPause sent`),
  close: () => select(null),
  sendToType: () => sendSelectedToType(details.chosenStationType()),
  service: () => toggleService(),
  select,
});

function statusOf(vehicle, nowS) {
  return vehicleStatus(vehicle, store.trafficOf(vehicle.id), nowS);
}

function schedule() {
  if (ui.frameRequested) return;
  ui.frameRequested = true;
  requestAnimationFrame(frame);
}

function frame() {
  const started = performance.now();
  ui.frameRequested = false;
  if (store.fresh) redrawAll();
  if (store.removedVehicles.size) removeForgotten();
  const nowS = store.nowS();
  if (store.dirtyTraffic) for (const id of store.vehicles.keys()) store.dirtyVehicles.add(id);
  const selectedDirty = ui.selectionChanged || store.dirtyTraffic ||
    store.dirtyVehicles.has(ui.selected) || (ui.selected !== null && store.dirtyOrders);
  for (const id of store.dirtyVehicles) {
    const vehicle = store.vehicles.get(id);
    if (vehicle) paintVehicle(vehicle, nowS);
  }
  store.dirtyVehicles.clear();
  if (store.dirtyOrders) {
    paintOrders($("#order-list tbody"), store.orders, Date.now(), select, queueActions);
  }
  if (selectedDirty) paintSelection(nowS);
  store.dirtyOrders = store.dirtyTraffic = ui.selectionChanged = false;
  probe.painted(store.received);
  probe.served(store.serverDelays);
  store.received = [];
  store.serverDelays = [];
  probe.worked(performance.now() - started);
}

function redrawAll() {
  store.fresh = false;
  map.drawGraph(store.graph);
  map.drawLegend($("#legend"), store.graph);
  details.setStationTypes(stationTypes(store.graph));
  map.removeMissing(new Set(store.vehicles.keys()));
  vehicleList.rebuild(store.vehicles.keys());
  alarmList.paint(store.vehicles.values(), Date.now());
  if (!ui.fitted) map.fit([...store.vehicles.values()]);
  ui.fitted = true;
  window.vdaMap.ready = true;
}

// Vehicles the master forgot leave the map, the list and the selection.
function removeForgotten() {
  for (const id of store.removedVehicles) {
    vehicleList.remove(id);
    statuses.delete(id);
    if (ui.selected === id) {
      ui.selected = null;
      ui.selectionChanged = true;
    }
  }
  map.removeMissing(new Set(store.vehicles.keys()));
  store.removedVehicles.clear();
}

function paintVehicle(vehicle, nowS) {
  const status = statusOf(vehicle, nowS);
  statuses.set(vehicle.id, status);
  const selected = vehicle.id === ui.selected;
  map.paintVehicle(vehicle, status, selected);
  vehicleList.paint(vehicle, status, selected);
}

function paintSelection(nowS) {
  const vehicle = store.vehicles.get(ui.selected) || null;
  $("#map-stack").classList.toggle("targetable", Boolean(vehicle));
  drawOverlay(map.layers, map.nodes, store, vehicle);
  details.show(vehicle, vehicle ? statusOf(vehicle, nowS) : "idle",
    vehicle ? store.trafficOf(vehicle.id) : null, trafficActive());
}

// GET /traffic's answer may say {"enabled": false} instead of there being none.
function trafficActive() {
  return store.traffic !== null && store.traffic.enabled !== false;
}

function select(id) {
  const previous = ui.selected;
  ui.selected = store.vehicles.has(id) ? id : null;
  for (const changed of [previous, ui.selected]) if (changed) store.dirtyVehicles.add(changed);
  ui.selectionChanged = true;
  schedule();
}

// Once a second: silence that makes a vehicle offline sends no event, and order ages grow.
function everySecond() {
  const nowS = store.nowS();
  const counts = {};
  for (const vehicle of store.vehicles.values()) {
    const status = statusOf(vehicle, nowS);
    if (status !== statuses.get(vehicle.id)) store.dirtyVehicles.add(vehicle.id);
    counts[status] = (counts[status] || 0) + 1;
  }
  const parts = Object.entries(counts).sort().map(([status, n]) => `${n} ${status}`);
  $("#counts").textContent = `${store.vehicles.size} vehicles: ${parts.join(", ")}`;
  refreshAges($("#order-list tbody"), Date.now());
  alarmList.paint(store.vehicles.values(), Date.now());  // within a second of a change
  if (store.dirtyVehicles.size) schedule();
}

// -- acting -----------------------------------------------------------------------------------

function toast(message, kind = "ok") {
  const box = $("#toast");
  box.textContent = message;
  box.className = kind;
  box.setAttribute("data-kind", kind);
  box.hidden = false;
  clearTimeout(toast.timer);
  toast.timer = setTimeout(() => (box.hidden = true), kind === "error" ? 10000 : 5000);
}

function failed(err) {
  const hint = err instanceof ApiError && (err.status === 401 || err.status === 403)
    ? " (set the key with the API key button)" : "";
  toast(`${err.message}${hint}`, "error");
}

function act(call, describe) {
  const vehicle = store.vehicles.get(ui.selected);
  if (!vehicle) return;
  call(vehicle).then(() => toast(describe(vehicle)), failed);
}

// Out of service with the note typed beside the button, or back in service.
function toggleService() {
  const vehicle = store.vehicles.get(ui.selected);
  if (!vehicle) return;
  const putBack = vehicle.inService === false;
  const note = putBack ? "" : details.takeServiceNote();
  setInService(vehicle, putBack, note).then(() => toast(putBack
    ? `${vehicle.serialNumber} is back in service`
    : `${vehicle.serialNumber} is out of service: master control sends it no order`), failed);
}

const queueActions = {
  cancel: (orderId) =>
    cancelOrder(orderId).then(() => toast(`waiting order ${orderId} cancelled`), failed),
  first: (orderId, priority) =>
    setPriority(orderId, priority).then(
      (answer) => toast(`waiting order ${orderId} is now number ${answer.queuePosition} ` +
        `in the queue (priority ${priority})`),
      failed,
    ),
};

function sendSelectedTo(nodeId) {
  const vehicle = store.vehicles.get(ui.selected);
  if (!vehicle) {
    toast("select a vehicle first (on the map or in the list), then click a node");
    return;
  }
  sendTo(vehicle, nodeId).then(
    (answer) => toast(`order ${answer.orderId} sent: ${vehicle.serialNumber} to node ${nodeId}`),
    failed,
  );
}

function sendSelectedToType(stationType) {
  const vehicle = store.vehicles.get(ui.selected);
  if (!vehicle || !stationType) return;
  sendToStationType(vehicle, stationType).then(
    (answer) => toast(`order ${answer.orderId} sent: ${vehicle.serialNumber} to node ` +
      `${answer.destination} (the nearest ${stationType})`),
    failed,
  );
}

function stationTypes(graph) {
  const types = new Set((graph?.nodes || []).map((n) => n.stationType).filter(Boolean));
  return [...types].sort();
}

const zones = new ZoneDraw(map, $("#draft"), { BLOCKED: $("#block-area"), SPEED_LIMIT: $("#slow-area") }, {
  add: addZone,
  lift: liftZone,
  say: (text) => toast(text),
  failed,
  names: () => (store.graph?.zones || []).map((z) => z.zoneId),
});

// -- start ------------------------------------------------------------------------------------

window.vdaMap = { ready: false, store, probe, statuses, select };
takeKeyFromUrl();
// The whole fleet at once; the toast names the vehicles that were not sent it, and why.
function actOnFleet(actionType) {
  fleetInstantAction(actionType).then((answer) => {
    const refused = answer.results.filter((r) => r.status !== 202);
    const sent = `${actionType} sent to ${answer.sent} of ${answer.results.length} vehicles`;
    if (!refused.length) {
      toast(sent);
      return;
    }
    toast(`${sent}; not to ${refused.map((r) => r.detail).join("; ")}`, "error");
  }, failed);
}

$("#pause-all").addEventListener("click", () => actOnFleet("startPause"));
$("#resume-all").addEventListener("click", () => actOnFleet("stopPause"));
$("#fit").addEventListener("click", () => map.fit([...store.vehicles.values()]));
$("#key").addEventListener("click", () => {
  const key = window.prompt("API key for this tab (empty: none)", apiKey());
  if (key !== null) setApiKey(key.trim());
});
openStream("/events", {
  onOpen: () => {
    $("#link").textContent = "live";
    $("#link").dataset.state = "live";
  },
  onLost: (reason) => {
    $("#link").textContent = `reconnecting (${reason})`;
    $("#link").dataset.state = "lost";
  },
  onEvent: (name, data) => {
    if (name === "snapshot") store.applySnapshot(data);
    else if (name === "changes") store.applyChanges(data);
    schedule();
  },
});
setInterval(everySecond, 1000);
