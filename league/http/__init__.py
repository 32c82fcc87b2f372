"""The league's HTTP side: the FastAPI app, its edge guards and the JSON API's routes.

Only this package and :mod:`league.web` import FastAPI or Starlette; the worker and the
scheduler never load them.
"""
