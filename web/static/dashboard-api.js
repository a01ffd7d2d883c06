// The dashboard's calls to its own API: the session cookie, the header that marks a
// request as the dashboard's (changes without it are refused), the login page when the
// session has ended, and the API's error detail, with the fields it names, as the thrown
// message.
"use strict";
window.dashboardCall = async (path, options = {}) => {
  const response = await fetch(path, {
    ...options,
    headers: { "X-Requested-With": "ideeprl-dashboard", "Content-Type": "application/json" },
    cache: "no-store",
  });
  if (response.status === 401) {
    window.location.assign("/dashboard/login");
    throw new Error("logged out");
  }
  const body = response.status === 204 ? {} : await response.json().catch(() => ({}));
  if (!response.ok) {
    // a 422 names each field it refuses (`design.capacity: ...`), as the API's `loc` does
    const where = (d) => (Array.isArray(d.loc) ? d.loc.filter((p) => p !== "body").join(".") : "");
    const detail = Array.isArray(body.detail)
      ? body.detail.map((d) => (where(d) ? `${where(d)}: ${d.msg}` : d.msg)).join("; ")
      : body.detail;
    throw new Error(detail || `error ${response.status}`);
  }
  return body;
};
