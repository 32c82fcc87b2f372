// Server-Sent Events read with fetch and a stream reader: an EventSource cannot send the
// bearer token, which the training routes need.
"use strict";

const EventStream = {
  // One SSE block ("event: x\nid: 3\ndata: {...}") as {event, id, data}, or null for a comment.
  parse(block) {
    const found = { event: "message", id: null, data: [] };
    for (const line of block.split("\n")) {
      if (!line || line.startsWith(":")) continue;
      const colon = line.indexOf(":");
      const key = colon < 0 ? line : line.slice(0, colon);
      const value = colon < 0 ? "" : line.slice(colon + 1).replace(/^ /, "");
      if (key === "data") found.data.push(value);
      else if (key === "event") found.event = value;
      else if (key === "id") found.id = Number(value);
    }
    return found.data.length ? { event: found.event, id: found.id, data: JSON.parse(found.data.join("\n")) } : null;
  },

  // Follow `path` from the event after `lastId`, calling onEvent({event, id, data}) for
  // each; resolves with the HTTP status once the server ends the stream.
  async follow(path, lastId, onEvent) {
    const headers = { Accept: "text/event-stream" };
    if (Slip.token()) headers.Authorization = "Bearer " + Slip.token();
    if (lastId) headers["Last-Event-ID"] = String(lastId);
    const response = await fetch(path, { headers });
    if (!response.ok || !response.body) return response.status;
    const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
    let buffer = "";
    for (;;) {
      const { value, done } = await reader.read();
      if (done) return response.status;
      buffer += value;
      let cut;
      while ((cut = buffer.indexOf("\n\n")) >= 0) {
        const event = EventStream.parse(buffer.slice(0, cut));
        buffer = buffer.slice(cut + 2);
        if (event) onEvent(event);
      }
    }
  },
};
