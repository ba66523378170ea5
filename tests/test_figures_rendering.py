"""The report's figures rendered in a pool of processes (bench.figures.rendering_in):
the same PNG bytes as drawn in the report's own process, written whole when the
block ends, none when it ends in an error."""

import pytest

from radarbench.bench import figures
from radarbench.bench.run.processes import process_pool
from radarbench.bench.figures import plt


def _figure(title: str):
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot([0, 1, 2], [1, 0, 2], "o-", label=title)
    figures._legend_outside(ax)
    fig.set_layout_engine("tight")
    ax.set_title(title)
    return fig


@pytest.fixture(scope="module")
def pool():
    with process_pool(2) as p:
        yield p


def test_a_pool_renders_the_bytes_the_process_itself_renders(tmp_path, pool):
    figures._save(_figure("here"), tmp_path / "here.png")
    with figures.rendering_in(pool):
        figures._save(_figure("here"), tmp_path / "pool" / "here.png")
    assert (tmp_path / "pool" / "here.png").read_bytes() == (tmp_path / "here.png").read_bytes()
    assert not plt.get_fignums()                 # every figure closed in this process


def test_the_pngs_are_written_when_the_block_ends(tmp_path, pool):
    with figures.rendering_in(pool):
        path = figures._save(_figure("a"), tmp_path / "a.png")
        assert path == tmp_path / "a.png" and not path.exists()
    assert path.read_bytes().startswith(b"\x89PNG")


def test_an_error_in_the_block_writes_no_png(tmp_path, pool):
    with pytest.raises(ValueError), figures.rendering_in(pool):
        figures._save(_figure("b"), tmp_path / "b.png")
        raise ValueError("a section failed")
    assert not (tmp_path / "b.png").exists()
    assert [p.name for p in tmp_path.iterdir()] == []        # no temporary file either


def test_without_a_pool_the_figure_is_written_at_once(tmp_path):
    with figures.rendering_in(None):
        path = figures._save(_figure("c"), tmp_path / "c.png")
        assert path.exists()


class _BrokenAfterSubmit:
    """An executor whose every job fails as a pool does when its process dies."""

    def submit(self, fn, *args):
        from concurrent.futures import Future
        from concurrent.futures.process import BrokenProcessPool
        job = Future()
        job.set_exception(BrokenProcessPool("a process of the pool died"))
        return job


def test_a_pool_that_breaks_costs_speed_never_a_figure(tmp_path, capsys, monkeypatch):
    """A broken pool (a process killed, or one that could not start): the figures are
    drawn here instead, the same bytes, said once on stderr."""
    import os

    monkeypatch.setattr(figures, "_broken_said", False)
    figures._save(_figure("d"), tmp_path / "here.png")
    with figures.rendering_in(_BrokenAfterSubmit()):
        figures._save(_figure("d"), tmp_path / "after.png")
        figures._save(_figure("d"), tmp_path / "again.png")
    with process_pool(1) as dead:
        with pytest.raises(Exception):
            dead.submit(os._exit, 1).result()             # the pool is broken from here on
        with figures.rendering_in(dead):
            figures._save(_figure("d"), tmp_path / "refused.png")
    expected = (tmp_path / "here.png").read_bytes()
    assert all((tmp_path / f"{name}.png").read_bytes() == expected for name in ("after", "again", "refused"))
    err = capsys.readouterr().err
    assert err.count("bench: the figure processes stopped") == 1, err
