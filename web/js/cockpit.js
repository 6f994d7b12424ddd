// Opening Cockpit as the pilot, from a page that is logged in: the vehicle
// makes a Cockpit link (POST /api/cockpit-link, the login cookie shows who
// asks), a token good for its first use within a couple of minutes and then
// only from this machine, inside the mavlink2rest URL; Cockpit is opened
// with it (`?MAVLink2RestWebsocketURI=`, which Cockpit reads from its own
// address and does not store), so nobody types a password into a URL.
// Where Cockpit is served is asked once and kept in this browser.
const $ = (id) => document.getElementById(id);
const KEY = 'neptunus-cockpit-url';

export class CockpitLink {
  /** `view`: for the alert history (view.js). */
  constructor(view) {
    this.view = view;
  }

  bind() {
    $('cockpit-url').value = localStorage.getItem(KEY) || '';
    $('cockpit').onsubmit = (e) => {
      e.preventDefault();
      this.open();
    };
  }

  async open() {
    const note = $('cockpit-note');
    let target;
    try {
      target = new URL($('cockpit-url').value.trim());
      if (!['http:', 'https:'].includes(target.protocol)) throw new Error('not http');
    } catch {
      note.textContent = "give Cockpit's address as you open it, e.g. http://localhost:8000/";
      return;
    }
    localStorage.setItem(KEY, target.href);
    let body = {};
    try {
      const r = await fetch('/api/cockpit-link', { method: 'POST' });
      body = await r.json();
    } catch {
      note.textContent = 'the vehicle did not answer: try again';
      return;
    }
    if (!body.ok) {
      note.textContent = body.message || 'the vehicle made no link';
      return;
    }
    target.searchParams.set('MAVLink2RestWebsocketURI', body.mavlink);
    window.open(target.href, '_blank', 'noopener');
    note.textContent = `Cockpit opened as the pilot (the link works once within ${body.first_use_within_s} s, then from this machine only)`;
    this.view.message(6, 'Cockpit opened with this login');
  }
}
