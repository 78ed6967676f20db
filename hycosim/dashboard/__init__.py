"""The web dashboard: watch a running co-simulation (a passive Zenoh subscriber plus the
server's status queryable) or a finished run's directory, in a browser.

``live`` gathers what a running server and its nodes publish, ``finished`` reads a run
directory, ``series`` thins values for the browser, and ``app`` serves the page (Starlette
on uvicorn, with a WebSocket feed) from the files in ``static/``, uPlot among them: nothing
is fetched from elsewhere, so the page works on an offline plant network.
"""
