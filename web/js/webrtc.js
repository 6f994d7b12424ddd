// The camera over WebRTC: the vehicle's signalling WebSocket on /webrtc
// (mavlink-camera-manager's protocol, as Cockpit speaks it: peerId,
// availableStreams, startSession; the vehicle offers, the page answers; ICE
// candidates both ways) and the browser's own H.264 decoder. It calls
// `onFrame(video, width, height)` for every frame the <video> shows and
// `onEnd(reason)` once when the session cannot go on; what to do then is
// the caller's (video.js falls back to MJPEG). No DOM but the caller's
// <video> it plays in.

const q = (type, content) => JSON.stringify(content === undefined
  ? { type: 'question', content: { type } }
  : { type: 'question', content: { type, content } });
const negotiation = (type, content) => JSON.stringify({ type: 'negotiation', content: { type, content } });

/** Asks the browser to hold no frame back for smoothness: a pilot wants
 * the newest picture, not an even one (the vehicle asks the same with the
 * playout-delay RTP header extension). `jitterBufferTarget` is the
 * standard's, `playoutDelayHint` an older Chromium name; each only where
 * the browser has it. */
export function showAtOnce(receiver) {
  for (const name of ['jitterBufferTarget', 'playoutDelayHint']) {
    if (!(name in receiver)) continue;
    try {
      receiver[name] = 0;
    } catch {
      // A browser that refuses the value keeps its own.
    }
  }
}

export class WebRtcVideo {
  /** `video`: the <video> to play in; `iceServers`: as the vehicle lists
   * them (/api/webrtc). */
  constructor({ video, iceServers = [], onFrame = () => {}, onEnd = () => {} }) {
    this.iceServers = iceServers;
    this.onFrame = onFrame;
    this.onEnd = onEnd;
    this.ended = false;
    this.ws = null;
    this.pc = null;
    this.bind = null;
    this.video = video;
    this.video.muted = true;
    this.video.playsInline = true;
    this.video.autoplay = true;
  }

  /** Opens the signalling at `url` (ws:// or wss://). */
  start(url) {
    let consumer = null;
    let stream = null;
    const ws = new WebSocket(url);
    this.ws = ws;
    const ask = () => {
      if (!consumer || !stream || this.bind) return;
      ws.send(q('startSession', { consumer_id: consumer, producer_id: stream.id }));
    };
    ws.onopen = () => {
      ws.send(q('peerId'));
      ws.send(q('availableStreams'));
    };
    ws.onerror = () => this.end('the signalling WebSocket failed');
    ws.onclose = () => this.end('the signalling WebSocket closed');
    ws.onmessage = (ev) => {
      let m;
      try {
        m = JSON.parse(ev.data);
      } catch {
        return;
      }
      const c = m.content || {};
      if (m.type === 'error') {
        this.end(`the vehicle refused: ${c}`);
      } else if (m.type === 'answer' && c.type === 'peerId') {
        consumer = c.content.id;
        ask();
      } else if (m.type === 'answer' && c.type === 'availableStreams') {
        if (!c.content.length) this.end('the vehicle lists no stream');
        stream = stream || c.content[0];
        ask();
      } else if (m.type === 'answer' && c.type === 'startSession') {
        this.session(c.content);
      } else if (m.type === 'negotiation' && this.bind && c.content && c.content.session_id === this.bind.session_id) {
        if (c.type === 'mediaNegotiation') this.offer(c.content.sdp).catch((e) => this.end(`the offer: ${e}`));
        if (c.type === 'iceNegotiation' && this.pc) this.pc.addIceCandidate(c.content.ice).catch(() => {});
      } else if (m.type === 'question' && c.type === 'endSession' && this.bind && c.content.session_id === this.bind.session_id) {
        this.end(`the vehicle ended the session: ${c.content.reason}`);
      }
    };
  }

  session(bind) {
    this.bind = bind;
    const pc = new RTCPeerConnection({ iceServers: this.iceServers });
    this.pc = pc;
    pc.addTransceiver('video', { direction: 'recvonly' });
    pc.ontrack = (ev) => {
      showAtOnce(ev.receiver);
      this.video.srcObject = ev.streams[0] || new MediaStream([ev.track]);
      this.video.play().catch(() => {});
      const frame = (_now, meta) => {
        if (this.ended) return;
        this.onFrame(this.video, meta.width, meta.height);
        this.video.requestVideoFrameCallback(frame);
      };
      this.video.requestVideoFrameCallback(frame);
    };
    pc.onicecandidate = (ev) => {
      if (!ev.candidate || this.ws.readyState !== WebSocket.OPEN) return;
      this.ws.send(negotiation('iceNegotiation', { ...bind, ice: ev.candidate.toJSON() }));
    };
    pc.onconnectionstatechange = () => {
      if (pc.connectionState === 'failed') this.end('the connection failed (no route to the vehicle for WebRTC)');
    };
  }

  async offer(sdp) {
    await this.pc.setRemoteDescription(sdp);
    await this.pc.setLocalDescription(await this.pc.createAnswer());
    this.ws.send(negotiation('mediaNegotiation', { ...this.bind, sdp: this.pc.localDescription.toJSON() }));
  }

  /** Ends the session (once); `reason` goes to `onEnd`. */
  end(reason) {
    if (this.ended) return;
    this.ended = true;
    if (this.ws && this.ws.readyState === WebSocket.OPEN && this.bind) {
      this.ws.send(q('endSession', { ...this.bind, reason: 'the page stopped watching' }));
    }
    try { this.ws?.close(); } catch { /* already closed */ }
    try { this.pc?.close(); } catch { /* already closed */ }
    this.video.srcObject = null;
    this.onEnd(reason);
  }
}
