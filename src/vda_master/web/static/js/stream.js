// The live stream (/events, Server-Sent Events) read with fetch(), so that it can carry the
// API key header (EventSource cannot send headers). Reconnects with capped backoff; every new
// connection starts with a snapshot, so nothing is lost while it was away.

import { authHeaders, errorDetail } from "./api.js";

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// Calls onEvent(name, data) for every event, onOpen() and onLost(reason) on link changes.
export function openStream(url, { onEvent, onOpen, onLost }) {
  let attempt = 0;
  const run = async () => {
    for (;;) {
      try {
        const response = await fetch(url, {
          headers: { Accept: "text/event-stream", ...authHeaders() },
          cache: "no-store",
        });
        if (!response.ok) throw new Error(await errorDetail(response));
        attempt = 0;
        onOpen();
        await readEvents(response.body, onEvent);
        onLost("the stream ended");
      } catch (err) {
        onLost(err.message);
      }
      await sleep(Math.min(5000, 250 * 2 ** attempt));
      attempt += 1;
    }
  };
  run();
}

async function readEvents(body, onEvent) {
  const reader = body.pipeThrough(new TextDecoderStream()).getReader();
  let buffer = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer += value;
    let end = buffer.indexOf("\n\n");
    while (end >= 0) {
      dispatch(buffer.slice(0, end), onEvent);
      buffer = buffer.slice(end + 2);
      end = buffer.indexOf("\n\n");
    }
  }
}

function dispatch(block, onEvent) {
  let name = "message";
  let data = "";
  for (const line of block.split("\n")) {
    if (line.startsWith("event: ")) name = line.slice(7);
    else if (line.startsWith("data: ")) data += line.slice(6);
  }
  if (data) onEvent(name, JSON.parse(data));
}
