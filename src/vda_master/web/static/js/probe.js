// Measurements the browser tests and benchmarks/map.py read through window.vdaMap:
// - latency: from the master receiving a vehicle's message (its `rx` stamp, epoch ms) to the
//   first animation frame after the change was written to the DOM (so it has been painted);
// - script time: how long each of the page's frame updates ran (ms);
// - frame times: requestAnimationFrame deltas over a window.

const KEEP = 20000;

export class Probe {
  constructor() {
    this.latencies = [];
    this.serverMs = [];
    this.scriptMs = [];
  }

  // The master's share of the latency: received -> sent on the stream.
  served(delays) {
    for (const delay of delays) this.serverMs.push(delay);
    if (this.serverMs.length > KEEP) this.serverMs.splice(0, this.serverMs.length - KEEP);
  }

  worked(ms) {
    this.scriptMs.push(ms);
    if (this.scriptMs.length > KEEP) this.scriptMs.splice(0, this.scriptMs.length - KEEP);
  }

  // Called by the frame that wrote changes received at `stamps` into the DOM.
  painted(stamps) {
    if (!stamps.length) return;
    requestAnimationFrame(() => {
      const now = performance.timeOrigin + performance.now();
      for (const rx of stamps) this.latencies.push(now - rx);
      if (this.latencies.length > KEEP) this.latencies.splice(0, this.latencies.length - KEEP);
    });
  }

  // requestAnimationFrame deltas (ms) over the next `durationMs`.
  frames(durationMs) {
    return new Promise((resolve) => {
      const deltas = [];
      let last = null;
      const end = performance.now() + durationMs;
      const step = (time) => {
        if (last !== null) deltas.push(time - last);
        last = time;
        if (time < end) requestAnimationFrame(step);
        else resolve(deltas);
      };
      requestAnimationFrame(step);
    });
  }
}
