// The master's HTTP API as the page uses it. Every failure becomes an Error carrying the API's
// own `detail` message. An API key, when one is set, goes with every request (both header forms
// the master may accept); it comes from `?key=` in the page URL or from the "API key" button and
// is kept in sessionStorage for this tab only.

const KEY_ITEM = "vda-master-api-key";

export function takeKeyFromUrl() {
  const url = new URL(window.location.href);
  const key = url.searchParams.get("key");
  if (key !== null) {
    setApiKey(key);
    url.searchParams.delete("key");
    window.history.replaceState(null, "", url);
  }
}

export function apiKey() {
  return window.sessionStorage.getItem(KEY_ITEM) || "";
}

export function setApiKey(key) {
  if (key) window.sessionStorage.setItem(KEY_ITEM, key);
  else window.sessionStorage.removeItem(KEY_ITEM);
}

export function authHeaders() {
  const key = apiKey();
  return key ? { "X-API-Key": key, Authorization: `Bearer ${key}` } : {};
}

export class ApiError extends Error {
  constructor(status, detail) {
    super(detail);
    this.status = status;
  }
}

// The `detail` of an error answer, or a description of the answer when it has none.
export async function errorDetail(response) {
  let detail = `${response.status} ${response.statusText}`;
  try {
    const body = await response.json();
    if (body && typeof body.detail === "string") detail = body.detail;
    else if (body && body.detail) detail = JSON.stringify(body.detail);
  } catch {
    // not JSON: keep the status line
  }
  return detail;
}

export async function request(method, path, body) {
  const headers = { Accept: "application/json", ...authHeaders() };
  const init = { method, headers };
  if (body !== undefined) {
    headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  let response;
  try {
    response = await fetch(path, init);
  } catch (err) {
    throw new ApiError(0, `the master cannot be reached (${err.message})`);
  }
  if (!response.ok) throw new ApiError(response.status, await errorDetail(response));
  return response.status === 204 ? null : response.json();
}

export function sendTo(vehicle, nodeId) {
  return request("POST", "/orders", {
    manufacturer: vehicle.manufacturer,
    serialNumber: vehicle.serialNumber,
    destination: nodeId,
  });
}

export function sendToStationType(vehicle, stationType) {
  return request("POST", "/orders", {
    manufacturer: vehicle.manufacturer,
    serialNumber: vehicle.serialNumber,
    stationType,
  });
}

export function cancelOrder(orderId) {
  return request("DELETE", `/orders/${encodeURIComponent(orderId)}`);
}

export function setPriority(orderId, priority) {
  return request("PATCH", `/orders/${encodeURIComponent(orderId)}`, { priority });
}

export function instantAction(vehicle, actionType) {
  const path = `/vehicles/${encodeURIComponent(vehicle.manufacturer)}/` +
    `${encodeURIComponent(vehicle.serialNumber)}/instantActions`;
  return request("POST", path, { actions: [{ actionType }] });
}

// Out of service (inService false, with a note saying why) or back in service.
export function setInService(vehicle, inService, note = "") {
  const path = `/vehicles/${encodeURIComponent(vehicle.manufacturer)}/` +
    `${encodeURIComponent(vehicle.serialNumber)}`;
  return request("PATCH", path, { inService, note });
}

// One instant action to every vehicle: {sent, results: [{manufacturer, serialNumber, status,
// actionIds | detail}]}.
export function fleetInstantAction(actionType) {
  return request("POST", "/vehicles/instantActions", { actions: [{ actionType }] });
}

export function addZone(zone) {
  return request("POST", "/zones", zone);
}

export function liftZone(zoneId) {
  return request("DELETE", `/zones/${encodeURIComponent(zoneId)}`);
}
