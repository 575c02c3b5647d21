// What the page knows, fed by the stream's snapshot and changes events. It only records which
// vehicles and orders changed; the frame loop (main.js) turns that into DOM work once per frame.

export const MAX_ORDERS = 50;

export class Store {
  constructor() {
    this.graph = null;
    this.vehicles = new Map(); // id "<manufacturer>/<serialNumber>" -> vehicle payload
    this.orders = new Map(); // orderId -> order payload, newest last
    this.traffic = null; // GET /traffic's answer, or null without traffic control
    this.trafficByVehicle = new Map();
    this.serverOffsetMs = 0; // master wall clock minus this browser's
    this.dirtyVehicles = new Set();
    this.removedVehicles = new Set(); // forgotten by the master since the last frame
    this.dirtyOrders = false;
    this.dirtyTraffic = false;
    this.fresh = false; // a snapshot replaced everything
    this.received = []; // receive stamps (ms) of applied vehicle changes, for the latency probe
    this.serverDelays = []; // per change: master received it -> master sent it (ms)
  }

  nowS() {
    return (Date.now() + this.serverOffsetMs) / 1000;
  }

  applySnapshot(data) {
    this.serverOffsetMs = data.serverTime - Date.now();
    this.graph = data.graph;
    this.vehicles = new Map(data.vehicles.map((v) => [v.id, v]));
    this.orders = new Map();
    for (const order of [...data.orders].reverse()) this.orders.set(order.orderId, order);
    this.setTraffic(data.traffic);
    this.fresh = true;
    this.dirtyOrders = true;
    for (const id of this.vehicles.keys()) this.dirtyVehicles.add(id);
  }

  applyChanges(data) {
    for (const vehicle of data.vehicles || []) {
      this.vehicles.set(vehicle.id, vehicle);
      this.touch(vehicle.id, vehicle.rx, data.sent);
    }
    for (const pose of data.poses || []) {
      const vehicle = this.vehicles.get(pose.id);
      if (!vehicle) continue;
      Object.assign(vehicle, pose);
      this.touch(pose.id, pose.rx, data.sent);
    }
    for (const id of data.removed || []) {
      if (this.vehicles.delete(id)) this.removedVehicles.add(id);
      this.dirtyVehicles.delete(id);
    }
    for (const order of data.orders || []) this.applyOrder(order);
    if ("traffic" in data) this.setTraffic(data.traffic);
  }

  // An order changed: its vehicle's active order, and the recent list if it belongs there.
  applyOrder(order) {
    const vehicle = this.vehicles.get(order.vehicle);
    if (vehicle && (order.active || vehicle.activeOrderId === order.orderId)) {
      vehicle.activeOrderId = order.active ? order.orderId : null;
      vehicle.activeOrderStatus = order.active ? order.status : null;
      this.dirtyVehicles.add(vehicle.id);
    }
    const oldest = this.orders.values().next().value;
    const recent = this.orders.size < MAX_ORDERS || order.createdAt >= oldest.createdAt;
    if (!this.orders.has(order.orderId) && !recent) return;
    this.orders.set(order.orderId, order);
    const sorted = [...this.orders.values()].sort((a, b) => a.createdAt.localeCompare(b.createdAt));
    this.orders = new Map(sorted.slice(-MAX_ORDERS).map((o) => [o.orderId, o]));
    this.dirtyOrders = true;
  }

  touch(id, rx, sent) {
    this.dirtyVehicles.add(id);
    if (!rx) return;
    this.received.push(rx);
    if (sent) this.serverDelays.push(sent - rx);
  }

  setTraffic(traffic) {
    this.traffic = traffic;
    this.trafficByVehicle = new Map(
      (traffic?.vehicles || []).map((t) => [`${t.manufacturer}/${t.serialNumber}`, t]),
    );
    this.dirtyTraffic = true;
  }

  trafficOf(id) {
    return this.trafficByVehicle.get(id) || null;
  }
}
