// The pilot's alerts: every message from the vehicle and the page, newest
// first, with its severity in words and its time; a count of warnings not
// yet seen; and, when the pilot turns it on, critical alerts spoken aloud
// (Web Speech API) so they are heard while the eyes are on the picture.
// docs/ARCHITECTURE.md is the map of the whole program.

const MAX_ALERTS = 200;
const SPEAK_KEY = 'neptunus.speakAlerts';
/** MAV_SEVERITY: 0 emergency … 7 debug. */
const WORDS = ['EMERGENCY', 'ALERT', 'CRITICAL', 'ERROR', 'WARNING', 'NOTICE', 'INFO', 'DEBUG'];
/** Spoken: emergency to error, and failsafes at any severity. */
const SPEAK_AT_OR_BELOW = 3;

export class Alerts {
  /** `list`: the <ol>; `badge`: the unseen-warnings count; `speakBox`: the checkbox. */
  constructor(list, badge, speakBox) {
    this.list = list;
    this.badge = badge;
    this.speakBox = speakBox;
    this.unseen = 0;
    this.speakBox.checked = localStorage.getItem(SPEAK_KEY) === '1';
    this.speakBox.disabled = !('speechSynthesis' in window);
    this.speakBox.addEventListener('change', () => {
      localStorage.setItem(SPEAK_KEY, this.speakBox.checked ? '1' : '0');
      if (this.speakBox.checked) this.say('Spoken alerts on');
    });
    // Looking at the list counts as seeing it.
    this.list.addEventListener('pointerenter', () => this.seen());
    this.list.addEventListener('focusin', () => this.seen());
  }

  /** One alert; `failsafe` also speaks it whatever its severity. */
  add(severity, text, { failsafe = false } = {}) {
    const sev = Number.isInteger(severity) && severity >= 0 && severity <= 7 ? severity : 6;
    const li = document.createElement('li');
    li.className = `sev${sev}`;
    li.dataset.severity = WORDS[sev];
    const time = document.createElement('time');
    time.textContent = new Date().toLocaleTimeString();
    const tag = document.createElement('b');
    tag.textContent = WORDS[sev];
    li.append(time, ' ', tag, ' ', text);
    this.list.prepend(li);
    while (this.list.childElementCount > MAX_ALERTS) this.list.lastChild.remove();
    if (sev <= 4) {
      this.unseen += 1;
      this.showBadge();
    }
    if (sev <= SPEAK_AT_OR_BELOW || failsafe) this.say(text);
  }

  say(text) {
    if (!this.speakBox.checked || !('speechSynthesis' in window)) return;
    const u = new SpeechSynthesisUtterance(text.replace(/GCS/g, 'G C S'));
    u.rate = 1.1;
    window.speechSynthesis.speak(u);
  }

  seen() {
    this.unseen = 0;
    this.showBadge();
  }

  showBadge() {
    this.badge.hidden = this.unseen === 0;
    this.badge.textContent = String(this.unseen);
  }
}
