// Developer interface, the plots (thesis 7.2): up to 10 live uPlot charts
// of what recorder.js recorded since connection (headings unwrapped), zoom
// and pan, reset, CSV export. main.js imports this module when the
// developer view is first opened, so the plotting library and its
// stylesheet load then and never for the operator alone; the recorder and
// the logger run from connection on without it. docs/ARCHITECTURE.md is
// the map of the whole program.
import uPlot from '/vendor/uPlot.esm.js';
import { SIGNALS, HEADINGS } from '/js/recorder.js';

export const MAX_PLOTS = 10;

const $ = (id) => document.getElementById(id);

// uPlot's stylesheet comes with it, placed before the page's own so that
// the page's rules for `.uplot` still win.
const css = document.createElement('link');
css.rel = 'stylesheet';
css.href = '/vendor/uPlot.min.css';
document.head.insertBefore(css, document.head.querySelector('link[rel=stylesheet]'));

/** Binds the developer view's plot controls to `recorder` (recorder.js);
 * returns the plots. */
export function bindPlots(recorder) {
  const note = $('plot-note');
  const plots = new Plots($('plots'), recorder, (text) => { note.textContent = text; });
  $('add-plot').onclick = () => plots.add($('signal').value);
  $('remove-plots').onclick = () => plots.removeAll();
  $('reset-data').onclick = () => {
    recorder.reset();
    plots.reset();
    $('samples').textContent = '0';
  };
  $('export-csv').onclick = () => {
    const blob = new Blob([recorder.csv()], { type: 'text/csv' });
    const a = document.createElement('a');
    a.href = URL.createObjectURL(blob);
    a.download = `neptunus-${new Date().toISOString().replace(/[:.]/g, '-')}.csv`;
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 10000);
  };
  return plots;
}

export class Plots {
  constructor(el, recorder, note) {
    this.el = el;
    this.rec = recorder;
    this.note = note;
    this.plots = []; // {key, index, u, box, zoomed}
  }

  add(key) {
    if (this.plots.length >= MAX_PLOTS) {
      this.note(`At most ${MAX_PLOTS} plots at once: remove one to add another.`);
      return false;
    }
    const index = SIGNALS.findIndex(([k]) => k === key);
    if (index < 0) return false;
    const label = HEADINGS.has(key) ? `${SIGNALS[index][1]}, unwrapped` : SIGNALS[index][1];
    const box = document.createElement('div');
    box.className = 'plot';
    box.dataset.signal = key;
    const head = document.createElement('header');
    const title = document.createElement('b');
    title.textContent = label;
    const left = document.createElement('button');
    left.type = 'button';
    left.textContent = '◀';
    left.title = 'Pan left';
    const right = document.createElement('button');
    right.type = 'button';
    right.textContent = '▶';
    right.title = 'Pan right';
    const close = document.createElement('button');
    close.type = 'button';
    close.textContent = '×';
    close.title = 'Remove this plot';
    close.className = 'remove-plot';
    head.append(title, left, right, close);
    const area = document.createElement('div');
    box.append(head, area);
    this.el.append(box);
    const entry = { key, index, box, zoomed: false };
    const width = Math.max(300, (box.clientWidth || 340) - 10);
    entry.u = new uPlot(
      {
        width,
        height: 180,
        scales: { x: { time: false } },
        axes: [{ stroke: '#8fa7bd', grid: { stroke: '#2b4660' } }, { stroke: '#8fa7bd', grid: { stroke: '#2b4660' } }],
        series: [{ label: 't [s]' }, { label, stroke: '#4fc3f7', width: 1.5, spanGaps: false }],
        cursor: { drag: { x: true, y: false } },
        hooks: {
          setSelect: [() => { entry.zoomed = true; }],
        },
      },
      this.data(index),
      area,
    );
    area.addEventListener('dblclick', () => { entry.zoomed = false; this.refresh(); });
    const pan = (dir) => {
      const s = entry.u.scales.x;
      if (s.min == null || s.max == null) return;
      const d = (s.max - s.min) * 0.25 * dir;
      entry.zoomed = true;
      entry.u.setScale('x', { min: s.min + d, max: s.max + d });
    };
    left.addEventListener('click', () => pan(-1));
    right.addEventListener('click', () => pan(1));
    close.addEventListener('click', () => this.remove(entry));
    this.plots.push(entry);
    this.note('');
    return true;
  }

  data(index) {
    return [this.rec.time, this.rec.plotCols[index]];
  }

  remove(entry) {
    entry.u.destroy();
    entry.box.remove();
    this.plots = this.plots.filter((p) => p !== entry);
    this.note('');
  }

  removeAll() {
    [...this.plots].forEach((p) => this.remove(p));
  }

  /** New data into every plot; a zoomed or panned plot keeps its view. */
  refresh() {
    for (const p of this.plots) {
      // uPlot keeps references: hand it fresh array views so it redraws.
      p.u.setData([this.rec.time.slice(), this.rec.plotCols[p.index].slice()], !p.zoomed);
    }
  }

  /** After the recorder was reset: every plot empty and back to following
   * the data, a zoomed or panned one too (it would keep the old window). */
  reset() {
    for (const p of this.plots) {
      p.zoomed = false;
      p.u.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
      p.u.setData([[], []], true);
    }
  }
}
