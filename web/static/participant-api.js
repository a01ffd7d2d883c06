// What a participant's pages call on their API: the token from their link, JSON bodies,
// and the API's error detail (of a validation error, its first message) as the thrown
// Error, which carries the response's status.
"use strict";
window.participantCall = async (token, path, options = {}) => {
  const headers = { Authorization: `Bearer ${token}` };
  if (options.body !== undefined) headers["Content-Type"] = "application/json";
  const response = await fetch(path, { ...options, headers, cache: "no-store" });
  const body = await response.json().catch(() => ({}));
  if (!response.ok) {
    const detail = Array.isArray(body.detail) && body.detail.length ? body.detail[0].msg : body.detail;
    const error = new Error(typeof detail === "string" ? detail : `error ${response.status}`);
    error.status = response.status;
    throw error;
  }
  return body;
};

// The end of the induction (or of the check): start the session, then the advice page.
window.participantStart = async (token) => {
  await window.participantCall(token, "/api/participant/start", { method: "POST" });
  window.location.assign(`/p/${token}/advise`);
};
