"""The clinic's local web application (``rig serve``): patients by pseudonym, their sessions,
each session's report and files, the progress across visits — the same service functions the
CLI runs, in the browser. See ``docs/web.md``.

The rooms (arrows point down; nothing here imports :mod:`rig.commands`)::

    server.py     ServeRequest, run_server: uvicorn on a bound socket, the cache folder
      |
    app.py        create_app(settings): middleware, routers, errors as pages
      |
    pages.py      the HTML pages          api.py       the JSON API (/api/)
    live.py       the guided recording, the live coverage view (Server-Sent Events), a
                  session's boundary and training (its ``router``; pages and /api/)
    jobs.py       JobRunner (``app.state.jobs``): that long work off the request path, its
                  state in the store's ``jobs`` table
      |                                     |
    clinic.py     what both do: patients, sessions, reports (cached), progress, downloads
    security.py   users (Argon2), login, CSRF, body limit, headers, access-log filter
    render.py     templates, the error answer (page or JSON)
    settings.py   WebSettings
"""

from rig.web.settings import WebSettings

__all__ = ["WebSettings"]
