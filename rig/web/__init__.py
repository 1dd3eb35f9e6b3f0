"""The clinic's local web application (``rig serve``): the same service functions as the CLI.

:mod:`rig.web.live` — the guided recording, the live coverage view (Server-Sent Events) and a
session's boundary and training, as ``router``; :mod:`rig.web.jobs` — the long work those run
off the request path (:class:`~rig.web.jobs.JobRunner`, set as ``app.state.jobs``).
"""
