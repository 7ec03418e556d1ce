// Small DOM helpers for the side panel: fields, selects, lists, status, error.

export const $ = (id) => document.getElementById(id);

// An error found before asking the server (e.g. a field that is not a number).
export class LocalError extends Error {}

// Read a number field; throws LocalError naming the field if it is not a number.
export function num(id) {
  const el = $(id);
  const v = el.value.trim() === '' ? NaN : Number(el.value);
  if (!Number.isFinite(v)) throw new LocalError(`${id.replace(/-/g, ' ')}: not a number ('${el.value}')`);
  return v;
}

// Write a number into a field, rounded for display (0.1 mm / 1e-4 rad).
export function setNum(id, v) {
  $(id).value = String(Math.round(v * 1e4) / 1e4);
}

export function setNums(ids, values) {
  ids.forEach((id, i) => setNum(id, values[i]));
}

// Write numbers exactly (values taken from the spec, so "Update" keeps them).
export function setExact(ids, values) {
  ids.forEach((id, i) => { $(id).value = String(values[i]); });
}

export const nums = (ids) => ids.map(num);

// Refill a <select> with option values, keeping the current choice if possible.
export function fillSelect(id, values, preferred) {
  const sel = $(id);
  const keep = preferred ?? sel.value;
  sel.replaceChildren(...values.map((v) => {
    const o = document.createElement('option');
    o.value = v;
    o.textContent = v;
    return o;
  }));
  if (values.includes(keep)) sel.value = keep;
}

// Render a list: one <li data-KEY="name"> per item with a label, a small note
// and an optional delete button.
export function renderList(id, key, items, { label, note, swatch, selected, onClick, onDelete }) {
  const ul = $(id);
  ul.replaceChildren(...items.map((it) => {
    const li = document.createElement('li');
    li.dataset[key] = it.name;
    if (selected === it.name) li.classList.add('selected');
    if (swatch) {
      const s = document.createElement('span');
      s.className = 'swatch';
      s.style.background = swatch(it);
      li.append(s);
    }
    const span = document.createElement('span');
    span.className = 'label';
    span.textContent = label ? label(it) : it.name;
    if (note) {
      const small = document.createElement('small');
      small.textContent = ` ${note(it)}`;
      span.append(small);
    }
    li.append(span);
    li.addEventListener('click', () => onClick?.(it.name));
    if (onDelete) {
      const b = document.createElement('button');
      b.className = 'danger delete';
      b.title = `delete ${it.name}`;
      b.textContent = '✕';
      b.addEventListener('click', (e) => {
        e.stopPropagation();
        onDelete(it.name);
      });
      li.append(b);
    }
    return li;
  }));
}

// Status line: a message plus the "unsaved changes" marker.
export function setStatus(msg) {
  $('status-msg').textContent = msg;
}

export function setDirty(dirty) {
  $('dirty').textContent = dirty ? '● unsaved changes' : '';
}

export function showError(msg) {
  const el = $('error');
  el.textContent = msg;
  el.hidden = !msg;
}

export const clearError = () => showError('');
