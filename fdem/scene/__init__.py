"""Scene files: a slope described in TOML and run with ``fdem run my_slope.toml``.

:mod:`fdem.scene.schema` declares every key (type, unit, range, default) and checks a file
before any work; :mod:`fdem.scene.objects` and :mod:`fdem.scene.build` make the checked scene
into geometry, mesh and simulation; :mod:`fdem.scene.write` writes a scene back (the built-in
cases' ``--write-scene``). The runner is :mod:`fdem.cases.scene`; the guide is ``docs/scenes.md``.
"""
__all__: list[str] = []
