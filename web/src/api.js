// HTTP access to the `twinforge gui` server. Every call is JSON; a failure
// (HTTP error with {"error": ...}, non-JSON answer, network failure) throws an
// ApiError whose message is meant to be shown to the person as is.

export class ApiError extends Error {
  constructor(message, status = 0) {
    super(message);
    this.status = status;
  }
}

// Busy marker: document.body.dataset.busy is "1" while anything is in flight.
let inflight = 0;
export function busy(delta) {
  inflight = Math.max(0, inflight + delta);
  document.body.dataset.busy = inflight > 0 ? '1' : '0';
}

// One request; `path` is relative so the page also works behind a prefix.
export async function request(method, path, body) {
  busy(+1);
  try {
    let res;
    try {
      res = await fetch(path, {
        method,
        cache: 'no-store',
        headers: body !== undefined ? { 'Content-Type': 'application/json' } : {},
        body: body !== undefined ? JSON.stringify(body) : undefined,
      });
    } catch (e) {
      throw new ApiError(`network error (${method} ${path}): ${e.message}`);
    }
    const text = await res.text();
    let data;
    try {
      data = text ? JSON.parse(text) : null;
    } catch {
      data = undefined;
    }
    if (!res.ok) {
      const msg = data && typeof data.error === 'string'
        ? data.error
        : `${method} ${path}: HTTP ${res.status} ${text.slice(0, 200)}`;
      throw new ApiError(msg, res.status);
    }
    if (data === undefined) throw new ApiError(`${method} ${path}: the answer is not JSON`, res.status);
    return data;
  } finally {
    busy(-1);
  }
}

// The endpoints.
export const api = {
  twin: () => request('GET', 'api/twin'),
  scan: () => request('GET', 'api/scan'),
  part: (name) => request('GET', `api/part?name=${encodeURIComponent(name)}`),
  setSpec: (spec) => request('POST', 'api/spec', { spec }),
  undo: () => request('POST', 'api/undo', {}),
  save: () => request('POST', 'api/save', {}),
  exportScene: () => request('POST', 'api/export', {}),
};
