"""The i2v-loc yard service: REST API, WebSocket stream, live parameters, metrics and dashboard.

Start it with ``i2v-loc serve`` (see docs/service.md); build it in code with
``service.core.build_service`` and ``service.app.create_app``.
"""
