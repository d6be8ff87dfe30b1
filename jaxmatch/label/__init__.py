"""``jaxmatch label``: a local web page where designers pick the preferred mesh for shapes.

:mod:`jaxmatch.label.app` is the web app (Starlette, served by uvicorn), :mod:`jaxmatch.label.store`
the labels file (the JSON-lines format of :mod:`jaxmatch.tuning.labels`), ``static/`` the page.
See docs/labelling.md.
"""
