"""mkdocs hooks (mkdocs.yml, ``hooks``): the pages :mod:`bench.cli.docs` generates from the code,
added to the site and to its navigation after the hand-written pages, and the maths
renderer (:data:`bench.cli.docs.MATHJAX`), nothing written into the clone
(docs/architecture.md, 'Documentation')."""

from __future__ import annotations

from pathlib import Path

from radarbench.bench.cli.docs import MATHJAX, fill_measured, mathjax_script, pages

_generated: dict = {}


def on_config(config):
    from mkdocs.exceptions import ConfigurationError

    script = mathjax_script()
    if script is None:
        raise ConfigurationError("MathJax (the [docs] extra's django-static-mathjax) is not installed: "
                                 "pip install -e '.[docs]'")
    generated, nav = pages(Path(config.config_file_path).parent)
    _generated.clear()
    _generated.update(generated)
    _generated[MATHJAX] = script
    config.nav = list(config.nav or []) + nav
    return config


def on_files(files, config):
    from mkdocs.structure.files import File

    for path, content in _generated.items():
        if isinstance(content, Path):
            files.append(File.generated(config, path, abs_src_path=str(content)))
        else:
            files.append(File.generated(config, path, content=content))
    return files


def on_page_markdown(markdown, page, config, files):
    """A hand-written page's measured durations (:func:`bench.cli.docs.fill_measured`)."""
    return fill_measured(markdown, Path(config.config_file_path).parent, page.file.src_uri)
