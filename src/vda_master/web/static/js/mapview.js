// The SVG map: graph (nodes, directed edges, stations), legend, pan and zoom, and one marker per
// vehicle. Vehicle markers are only touched by paintVehicle(), called from the frame loop.

import { STATUSES, STATUS_LABELS } from "./status.js";
import { clear, degrees, edgeShape, svgEl, sx, sy } from "./svg.js";

const NODE_R = 0.3;
const STATION_HALF = 0.45;
const EDGE_OFFSET = 0.12; // two opposite edges between the same nodes are drawn side by side
const BODY = "-0.45,-0.3 0.25,-0.3 0.5,0 0.25,0.3 -0.45,0.3";
const KNOWN_STATIONS = new Set(["charging", "pick", "drop", "parking"]);
const ZONE_LEGEND = { BLOCKED: "blocked", SPEED_LIMIT: "speed limit", RELEASE: "one vehicle at a time" };

const LABEL_MIN_PX = 5; // labels smaller than this on screen are not drawn

export class MapView {
  // `stack` holds the graph's SVG (#map) and the vehicles' SVG (#live) on top of it.
  // `onDraw(clientX, clientY)` takes every click while `drawing()` is true (zonedraw.js);
  // `onZone(polygon)` a click on a zone.
  constructor(stack, { onNode, onVehicle, onZone = () => {}, onDraw = () => {}, drawing = () => false }) {
    this.stack = stack;
    this.svgs = [...stack.querySelectorAll("svg")];
    this.svg = this.svgs[0];
    this.layers = {};
    for (const id of ["edges", "holds", "route", "nodes", "waits", "vehicles", "draft"]) {
      this.layers[id] = stack.querySelector(`#${id}`);
    }
    this.markers = new Map(); // vehicle id -> {g, body, label, transform, status, text}
    this.nodes = new Map(); // nodeId -> graph node
    this.view = { x: -10, y: -10, w: 20, h: 20 };
    this.onNode = onNode;
    this.onVehicle = onVehicle;
    this.onZone = onZone;
    this.onDraw = onDraw;
    this.drawing = drawing;
    this.listen();
  }

  drawGraph(graph) {
    clear(this.layers.edges);
    clear(this.layers.nodes);
    this.nodes = new Map(graph.nodes.map((n) => [n.id, n]));
    for (const zone of graph.zones || []) this.drawZone(zone);
    for (const [entries, cls] of [[graph.blockedEdges || [], "edge blocked"], [graph.edges, "edge"]]) {
      for (const entry of entries) {
        const a = this.nodes.get(entry[1]);
        const b = this.nodes.get(entry[2]);
        if (!a || !b) continue;
        const [shape, attrs] = edgeShape(entry, a, b, EDGE_OFFSET, NODE_R + 0.05);
        svgEl(shape, { class: cls, "data-edge-id": entry[0], ...attrs }, this.layers.edges);
      }
    }
    for (const node of graph.nodes) this.drawNode(node);
  }

  // A zone of the graph file or added through the API: BLOCKED, SPEED_LIMIT or RELEASE (one
  // vehicle at a time; docs/master.md, Zones and Release zones).
  drawZone(zone) {
    const points = zone.vertices.map(([x, y]) => `${sx(x)},${sy(y)}`).join(" ");
    const shape = svgEl("polygon", { class: "zone", "data-zone-id": zone.zoneId,
      "data-zone-type": zone.zoneType, "data-zone-source": zone.source || "graph file", points },
    this.layers.edges);
    const title = svgEl("title", {}, shape);
    const limit = zone.maximumSpeed != null ? ` (at most ${zone.maximumSpeed} m/s)` : "";
    title.textContent = [`${zone.zoneType} ${zone.zoneId}${limit}`, zone.description]
      .filter(Boolean).join(" · ");
  }

  drawNode(node) {
    const g = svgEl("g", { class: "node", "data-node-id": node.id,
      transform: `translate(${sx(node.x)},${sy(node.y)})` }, this.layers.nodes);
    const title = svgEl("title", {}, g);
    title.textContent = [node.stationName, node.id, node.description].filter(Boolean).join(" · ");
    if (node.stationType) {
      g.setAttribute("data-station", KNOWN_STATIONS.has(node.stationType) ? node.stationType : "other");
      svgEl("rect", { x: -STATION_HALF, y: -STATION_HALF, width: 2 * STATION_HALF,
        height: 2 * STATION_HALF, rx: 0.08 }, g);
    } else {
      svgEl("circle", { r: NODE_R }, g);
    }
    const label = svgEl("text", { x: 0.5, y: 0.75 }, g);
    label.textContent = node.stationName ? `${node.stationName} (${node.id})` : node.id;
  }

  drawLegend(container, graph) {
    container.replaceChildren();
    const add = (cls, text) => {
      const row = document.createElement("div");
      row.className = "row";
      row.innerHTML = cls;
      row.append(text);
      container.append(row);
    };
    const title = (text) => {
      const row = document.createElement("div");
      row.className = "title";
      row.textContent = text;
      container.append(row);
    };
    title("vehicles");
    for (const status of STATUSES) {
      add(`<span class="swatch" data-status="${status}"></span>`, STATUS_LABELS[status]);
    }
    const types = [...new Set(graph.nodes.map((n) => n.stationType).filter(Boolean))].sort();
    if (types.length) title("stations");
    for (const type of types) {
      const kind = KNOWN_STATIONS.has(type) ? type : "other";
      add(`<svg viewBox="-1 -1 2 2"><g class="node" data-station="${kind}"><rect x="-0.8" y="-0.8" ` +
        `width="1.6" height="1.6" rx="0.15"></rect></g></svg>`, type);
    }
    const zoneTypes = [...new Set((graph.zones || []).map((z) => z.zoneType))].sort();
    if (zoneTypes.length) title("zones");
    for (const type of zoneTypes) {
      add(`<svg viewBox="0 0 14 14"><polygon class="zone" data-zone-type="${type}" ` +
        `points="1,1 13,1 13,13 1,13"></polygon></svg>`, ZONE_LEGEND[type] || type);
    }
    title("selected vehicle");
    add('<svg viewBox="0 0 14 14"><line x1="1" y1="7" x2="13" y2="7" stroke="#2563eb" stroke-width="3"/></svg>', "base (released)");
    add('<svg viewBox="0 0 14 14"><line x1="1" y1="7" x2="13" y2="7" stroke="#93c5fd" stroke-width="3" stroke-dasharray="3 2"/></svg>', "horizon");
    add('<svg viewBox="0 0 14 14"><line x1="1" y1="7" x2="13" y2="7" stroke="#fde68a" stroke-width="5"/></svg>', "reserved");
  }

  // Fit the view to the graph and the given vehicle positions.
  fit(vehicles = []) {
    const points = [...this.nodes.values(), ...vehicles.filter((v) => v.x !== null)];
    if (!points.length) return;
    const xs = points.map((p) => sx(p.x));
    const ys = points.map((p) => sy(p.y));
    const x = Math.min(...xs) - 1.5;
    const y = Math.min(...ys) - 1.5;
    this.setView({ x, y, w: Math.max(...xs) + 4 - x, h: Math.max(...ys) + 1.5 - y });
  }

  setView(view) {
    this.view = view;
    const box = `${view.x} ${view.y} ${view.w} ${view.h}`;
    for (const svg of this.svgs) svg.setAttribute("viewBox", box);
    this.stack.classList.toggle("far", 0.5 / this.unitsPerPixel() < LABEL_MIN_PX);
  }

  // One vehicle marker, created on first use; only changed attributes are written.
  paintVehicle(vehicle, status, selected) {
    let marker = this.markers.get(vehicle.id);
    if (!marker) marker = this.createMarker(vehicle);
    const placed = vehicle.x !== null && vehicle.y !== null;
    marker.g.classList.toggle("nopos", !placed);
    marker.g.classList.toggle("selected", selected);
    if (placed) {
      const transform = `translate(${sx(vehicle.x).toFixed(3)},${sy(vehicle.y).toFixed(3)})`;
      if (transform !== marker.transform) marker.g.setAttribute("transform", (marker.transform = transform));
      const turn = `rotate(${degrees(vehicle.theta || 0).toFixed(1)})`;
      if (turn !== marker.turn) marker.body.setAttribute("transform", (marker.turn = turn));
    }
    if (status !== marker.status) marker.g.setAttribute("data-status", (marker.status = status));
    const battery = vehicle.battery === undefined ? "" : ` ${Math.round(vehicle.battery)}%`;
    const text = `${vehicle.serialNumber}${battery}`;
    if (text !== marker.text) marker.label.textContent = marker.text = text;
  }

  createMarker(vehicle) {
    const g = svgEl("g", { class: "vehicle nopos", "data-vehicle": vehicle.id }, this.layers.vehicles);
    svgEl("circle", { class: "halo", r: 0.75 }, g);
    const body = svgEl("polygon", { class: "body", points: BODY }, g);
    const label = svgEl("text", { y: -0.95, "text-anchor": "middle" }, g);
    const marker = { g, body, label, transform: "", turn: "", status: "", text: "" };
    this.markers.set(vehicle.id, marker);
    return marker;
  }

  removeMissing(ids) {
    for (const [id, marker] of this.markers) {
      if (!ids.has(id)) {
        marker.g.remove();
        this.markers.delete(id);
      }
    }
  }

  // Pointer handling: drag pans, the wheel zooms around the cursor, a click (no drag) on a node
  // or vehicle reports it.
  listen() {
    const stack = this.stack;
    let drag = null;
    stack.addEventListener("pointerdown", (event) => {
      drag = { x: event.clientX, y: event.clientY, view: { ...this.view }, moved: false };
    });
    stack.addEventListener("pointermove", (event) => {
      // No button held: the pointer moves on after a click (drag is cleared a moment later).
      if (!drag || event.buttons === 0) return;
      const dx = event.clientX - drag.x;
      const dy = event.clientY - drag.y;
      if (!drag.moved && Math.hypot(dx, dy) < 4) return;
      if (!drag.moved) stack.setPointerCapture(event.pointerId);
      drag.moved = true;
      stack.classList.add("panning");
      const scale = this.unitsPerPixel();
      this.setView({ ...drag.view, x: drag.view.x - dx * scale, y: drag.view.y - dy * scale });
    });
    const end = () => {
      stack.classList.remove("panning");
      setTimeout(() => (drag = null), 0);
    };
    stack.addEventListener("pointerup", end);
    stack.addEventListener("pointercancel", end);
    stack.addEventListener("click", (event) => {
      if (drag && drag.moved) return;
      if (this.drawing()) return this.onDraw(event.clientX, event.clientY);
      const vehicle = event.target.closest("[data-vehicle]");
      if (vehicle) return this.onVehicle(vehicle.getAttribute("data-vehicle"));
      const node = event.target.closest("[data-node-id]");
      if (node) return this.onNode(node.getAttribute("data-node-id"));
      const zone = event.target.closest("polygon.zone[data-zone-id]");
      if (zone) this.onZone(zone);
    });
    stack.addEventListener("wheel", (event) => {
      event.preventDefault();
      const factor = Math.exp(event.deltaY * 0.0015);
      const point = this.toMap(event.clientX, event.clientY);
      const v = this.view;
      this.setView({ x: point.x - (point.x - v.x) * factor, y: point.y - (point.y - v.y) * factor,
        w: v.w * factor, h: v.h * factor });
    }, { passive: false });
  }

  unitsPerPixel() {
    const box = this.svg.getBoundingClientRect();
    if (!box.width || !box.height) return 1;
    return Math.max(this.view.w / box.width, this.view.h / box.height);
  }

  toMap(clientX, clientY) {
    const matrix = this.svg.getScreenCTM().inverse();
    const point = new DOMPoint(clientX, clientY).matrixTransform(matrix);
    return { x: point.x, y: point.y };
  }
}
