// A Foxglove WebSocket client (the npm package @foxglove/ws-protocol over `ws`), as Foxglove
// and Lichtblick attach to a live server: subscribes to the given topics and prints, one JSON
// object per line, each advertised channel it subscribed to and each message (payload in hex).
// Usage: node foxglove_client.js URL TOPICS_JSON COUNT. Exit 0 once COUNT messages of every
// topic came, 3 on timeout (30 s).
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [url, topicsJson, countText] = process.argv.slice(2);
const topics = JSON.parse(topicsJson);
const count = parseInt(countText, 10);
const client = new FoxgloveClient({
  ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const bySubscription = new Map();
const counts = {};
client.on("serverInfo", (info) => console.log(JSON.stringify({ serverInfo: info.name })));
client.on("advertise", (channels) => {
  for (const c of channels) {
    if (topics.includes(c.topic) && ![...bySubscription.values()].includes(c.topic)) {
      bySubscription.set(client.subscribe(c.id), c.topic);
      console.log(JSON.stringify({
        advertised: c.topic, encoding: c.encoding, schemaName: c.schemaName,
        schemaEncoding: c.schemaEncoding,
      }));
    }
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const topic = bySubscription.get(subscriptionId);
  counts[topic] = (counts[topic] || 0) + 1;
  const bytes = Buffer.from(data.buffer, data.byteOffset, data.byteLength);
  console.log(JSON.stringify({ topic, data: bytes.toString("hex") }));
  if (topics.every((t) => (counts[t] || 0) >= count)) {
    client.close();
    process.exit(0);
  }
});
client.on("error", (e) => {
  console.error(`error: ${e}`);
  process.exit(2);
});
setTimeout(() => {
  console.error(`timeout: ${JSON.stringify(counts)}`);
  process.exit(3);
}, 30000);
