// The advice page's 3-D view: where it loads from, keys that keep working after a drag,
// and what the robot holds, in words.
"use strict";
(() => {
  // Without a GPU (software WebGL) full-resolution rendering starves the page.
  function softwareWebGL() {
    try {
      const gl = document.createElement("canvas").getContext("webgl");
      if (!gl) return false;
      const info = gl.getExtension("WEBGL_debug_renderer_info");
      const renderer = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
      gl.getExtension("WEBGL_lose_context")?.loseContext();
      return /swiftshader|llvmpipe|softpipe|software/i.test(renderer);
    } catch {
      return false;
    }
  }

  // viser's client under /viewer/ of this server (or the configured viewer URL); its
  // websocket on the same host, wss when the page came over https; drawn at a lower
  // resolution without a GPU.
  window.sceneUrl = (iframe) => {
    const src = new URL(iframe.dataset.src, window.location.href);
    const socket = new URL(iframe.dataset.socket, src);
    socket.protocol = src.protocol === "https:" ? "wss:" : "ws:";
    socket.search = "";
    // viser reads `websocket` verbatim (no decoding): it must come unescaped.
    let url = `${src.origin}${src.pathname}?websocket=${socket.href}`;
    if (src.search.length > 1) url += `&${src.search.slice(1)}`;
    return softwareWebGL() ? `${url}&fixedDpr=0.75` : url;
  };

  // Dragging the view gives the frame the keyboard focus, and viser would take the arrow
  // keys for its camera. Hand focus back to the page as soon as the frame takes it: the
  // drag goes on (pointer events follow the pointer, not the focus) and the action keys
  // keep working.
  window.keepKeysOnPage = (iframe) => {
    const giveBack = () => {
      if (document.activeElement !== iframe) return;
      iframe.blur();
      window.focus();
    };
    window.addEventListener("blur", () => setTimeout(giveBack, 0));
    iframe.addEventListener("mouseleave", giveBack);
  };

  const STATIONS = { center: "above the center table", left: "at the left table", right: "at the right table" };

  window.describeStation = (station) => STATIONS[station] || "";

  // "The robot is holding the red cube, above the center table." (or holds nothing)
  window.describeArm = (state) => {
    const where = STATIONS[state.station] || "";
    if (!state.held) return `The robot is not holding anything${where ? `; it is ${where}` : ""}.`;
    return `The robot is holding the ${state.held.color} ${state.held.shape}${where ? `, ${where}` : ""}.`;
  };
})();
