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
    this.dirtyOrders = false;
    this.dirtyTraffic = false;
    this.fresh = false; // a snapshot replaced everything
    this.received = []; // receive stamps (ms) of applied vehicle changes, for the latency probe
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
      this.touch(vehicle.id, vehicle.rx);
    }
    for (const pose of data.poses || []) {
      const vehicle = this.vehicles.get(pose.id);
      if (!vehicle) continue;
      Object.assign(vehicle, pose);
      this.touch(pose.id, pose.rx);
    }
    for (const order of data.orders || []) {
      this.orders.delete(order.orderId);
      this.orders.set(order.orderId, order);
      this.dirtyOrders = true;
    }
    while (this.orders.size > MAX_ORDERS) this.orders.delete(this.orders.keys().next().value);
    if ("traffic" in data) this.setTraffic(data.traffic);
  }

  touch(id, rx) {
    this.dirtyVehicles.add(id);
    if (rx) this.received.push(rx);
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
