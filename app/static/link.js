// Shared links (app.logic.links): a page opened with settings in its query string hands them to
// the server once; ``url`` makes the link of the current settings, with this page's token. A
// session's page (/s/<id>/..., app.server.launcher) links to the launcher's root, so that whoever
// opens the link gets a session of their own with the same scene (``?lesson=KEY``: the lesson,
// its card, views and selection); it is given the token after "#"
// (never sent to a server). Once read, the token, the settings and the session's id leave the
// address bar (the page shows "/", whose reload opens a new session): a projected address gives
// nothing away. When the connection closes for good (the session ended), the page says so.
// The page loads its scripts before it mounts, all requested at once: this one changing the
// address does not change where the others are fetched from.
(() => {
  const query = new URLSearchParams(window.location.search);
  const hash = new URLSearchParams(window.location.hash.replace(/^#/, ''));
  const token = hash.get('token') || query.get('token');
  const root = window.location.pathname.replace(/^\/s\/[^/]+\/.*$/, '/');
  window.trame.utils.lmapdLink = {
    url(settings) {
      const head = token ? `token=${encodeURIComponent(token)}&` : '';
      return `${window.location.origin}${root}?${head}${settings || ''}`;
    },
    copy(settings) {
      const text = this.url(settings);
      if (navigator.clipboard) navigator.clipboard.writeText(text).catch(() => {});
      return text;
    },
    save(name, pending, type) {  // a download, unless the server refused it (null, with a message)
      Promise.resolve(pending).then((data) => {
        if (data !== null && data !== undefined) window.trame.utils.download(name, data, type);
      });
    },
  };
  query.delete('token');
  const lesson = query.get('lesson');  // a lesson's link (its card's "Share this lesson")
  query.delete('lesson');
  const given = Object.fromEntries(query);
  if (lesson) window.trame.trigger('open_lesson', [lesson]);
  else if (Object.keys(given).length) window.trame.trigger('open_link', [given]);
  let welcomed = true;  // a first visit in this browser gets the welcome line (app.ui.lessons)
  try { welcomed = window.localStorage.getItem('lmapd-welcomed') === '1'; } catch (e) { /* */ }
  window.trame.utils.lmapdWelcome = !welcomed && !lesson;  // read as the page mounts
  window.history.replaceState(null, document.title, root);
  const client = window.trame.state && window.trame.state.client;
  if (client && client.onConnectionClose) {
    client.onConnectionClose(() => {
      if (document.querySelector('.session-ended')) return;
      const note = document.createElement('div');
      note.className = 'session-ended';
      note.setAttribute('role', 'alert');
      note.textContent = 'Session ended: reload for a new one.';
      note.style.cssText = 'position:fixed;top:0;left:0;right:0;z-index:10000;padding:12px;'
        + 'background:#b71c1c;color:#fff;font:600 16px sans-serif;text-align:center';
      document.body.appendChild(note);
    });
  }
})();
