// Zones drawn on the map (POST /zones) and lifted again (DELETE /zones/{zoneId}): "Block an
// area" (BLOCKED) or "Slow an area" (SPEED_LIMIT, asks for the speed), then a click per corner;
// Enter, a double click or a click on the first corner closes the polygon, Escape gives up.
// The master answers with the zone (or says what is wrong with it) and every open map redraws
// from its next snapshot (docs/web.md).

import { svgEl, sx, sy } from "./svg.js";

const CLOSE_PX = 10; // a click this close to the first corner closes the polygon
const KINDS = {
  BLOCKED: { label: "Block an area", prefix: "blocked", verb: "block", closes: "closedEdges" },
  SPEED_LIMIT: { label: "Slow an area", prefix: "slow", verb: "slow down", closes: "limitedEdges" },
};

export class ZoneDraw {
  // `map`: the MapView; `layer`: where the draft is drawn; `buttons`: {BLOCKED, SPEED_LIMIT}
  // header buttons; `hooks`: {add(zone) -> Promise, lift(zoneId) -> Promise, say(text),
  // failed(err), names()}.
  constructor(map, layer, buttons, hooks) {
    this.map = map;
    this.layer = layer;
    this.buttons = buttons;
    this.hooks = hooks;
    this.kind = null; // the zone type being drawn
    this.corners = null; // [{x, y}] in map metres while drawing, else null
    for (const [kind, button] of Object.entries(buttons)) {
      button.addEventListener("click", () => (this.kind === kind ? this.stop() : this.start(kind)));
    }
    document.addEventListener("keydown", (event) => {
      if (!this.corners || (event.key !== "Escape" && event.key !== "Enter")) return;
      event.preventDefault(); // not also a press of the focused button
      if (event.key === "Escape") this.stop();
      else this.finish();
    });
  }

  get drawing() {
    return this.corners !== null;
  }

  start(kind) {
    this.stop();
    this.kind = kind;
    this.corners = [];
    this.map.stack.classList.add("drawing");
    this.buttons[kind].textContent = "Stop drawing";
    this.hooks.say(`click the corners of the area to ${KINDS[kind].verb}; Enter or the first ` +
      "corner closes it, Escape stops");
  }

  stop() {
    this.kind = null;
    this.corners = null;
    this.layer.replaceChildren();
    this.map.stack.classList.remove("drawing");
    for (const [kind, button] of Object.entries(this.buttons)) button.textContent = KINDS[kind].label;
  }

  // A click on the map while drawing (clientX/Y: where).
  click(clientX, clientY) {
    const point = this.map.toMap(clientX, clientY);
    const corner = { x: point.x, y: -point.y }; // SVG y points down (svg.js)
    const away = (c) => Math.hypot(sx(c.x) - point.x, sy(c.y) - point.y) / this.map.unitsPerPixel();
    const first = this.corners[0];
    if (first && this.corners.length >= 3 && away(first) <= CLOSE_PX) return this.finish();
    const last = this.corners[this.corners.length - 1];
    if (last && away(last) <= CLOSE_PX) return undefined; // the second click of a double click
    this.corners.push(corner);
    this.drawDraft();
  }

  drawDraft() {
    this.layer.replaceChildren();
    const points = this.corners.map((c) => `${sx(c.x)},${sy(c.y)}`).join(" ");
    svgEl("polygon", { class: "zone draft", "data-zone-type": this.kind, points }, this.layer);
    for (const c of this.corners) svgEl("circle", { class: "corner", cx: sx(c.x), cy: sy(c.y), r: 0.18 }, this.layer);
  }

  finish() {
    if (this.corners.length < 3) {
      this.hooks.say("a zone needs at least three corners");
      return;
    }
    const kind = KINDS[this.kind];
    const taken = new Set(this.hooks.names());
    let suggestion = `${kind.prefix}-1`;
    for (let n = 2; taken.has(suggestion); n += 1) suggestion = `${kind.prefix}-${n}`;
    const zoneId = window.prompt("Name of the area (its zoneId)", suggestion);
    if (zoneId === null) return; // keep drawing
    const zone = {
      zoneId: zoneId.trim(),
      zoneType: this.kind,
      vertices: this.corners.map((c) => ({ x: round(c.x), y: round(c.y) })),
      description: `drawn on the live map`,
    };
    if (this.kind === "SPEED_LIMIT") {
      const speed = window.prompt("Speed limit in the area (m/s)", "0.5");
      if (speed === null) return;
      zone.maximumSpeed = Number(speed);
    }
    this.hooks.add(zone).then((answer) => {
      this.stop();
      const edges = (answer[kind.closes] || []).length;
      const what = answer.zoneType === "BLOCKED" ? "blocks" : "slows";
      this.hooks.say(`zone ${answer.zoneId} ${what} ${edges} edge${edges === 1 ? "" : "s"}`);
    }, this.hooks.failed);
  }

  // A click on a zone (not while drawing): lift it, if it was added through the API.
  clickZone(polygon) {
    const zoneId = polygon.getAttribute("data-zone-id");
    if (polygon.getAttribute("data-zone-source") !== "api") {
      this.hooks.say(`zone ${zoneId} is part of the graph file: edit the file to change it`);
      return;
    }
    if (!window.confirm(`Lift zone ${zoneId}?`)) return;
    this.hooks.lift(zoneId).then(() => this.hooks.say(`zone ${zoneId} lifted`), this.hooks.failed);
  }
}

const round = (v) => Math.round(v * 1000) / 1000;
