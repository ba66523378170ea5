"""The default blueprint a recording carries, read back from its ``.rrd`` the way the viewer
gets it (``rerun.chunk.RrdReader``: the file's blueprint store), and the entities each view
shows: what the tests of the viewer's first screen check (docs/architecture.md,
'Recordings')."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

#: ``ContainerBlueprint:container_kind`` codes (rerun.blueprint.components.ContainerKind)
TABS, HORIZONTAL, VERTICAL, GRID = 1, 2, 3, 4


@dataclass
class View:
    kind: str                                  # the view class: TimeSeries, 2D, TextDocument...
    name: str
    origin: str
    queries: list[str] = field(default_factory=lambda: ["$origin/**"])
    legend_visible: bool | None = None         # None: no PlotLegend set

    def shows(self, entities) -> list[str]:
        """The entities among ``entities`` (escaped paths) that the view's queries include."""
        include, exclude = [], []
        for query in self.queries:
            sign, _, rule = query.strip().rpartition(" ")
            rule = rule.replace("$origin", "" if self.origin == "/" else self.origin)
            (exclude if sign == "-" else include).append(rule)
        return [e for e in entities if any(_matches(r, e) for r in include) and not any(_matches(r, e) for r in exclude)]


def _matches(rule: str, entity: str) -> bool:
    if rule.endswith("/**"):
        prefix = rule[:-3]
        return entity == (prefix or "/") or entity.startswith(prefix + "/")
    return entity == rule


@dataclass
class Container:
    kind: int
    name: str
    contents: list[str]                        # "view/ID" and "container/ID"


@dataclass
class Blueprint:
    root: str                                  # "container/ID"
    containers: dict[str, Container]
    views: dict[str, View]
    panels: dict[str, int]                     # panel -> state (1 hidden, 2 collapsed, 3 expanded)

    def child(self, ref: str) -> Container | View:
        return self.containers[ref] if ref.startswith("container/") else self.views[ref]

    def tab(self, *names: str, under: str | None = None) -> Container | View:
        """The tab of the root tab container named ``names[0]``, then in it the tab named ``names[1]``..."""
        ref = under or self.root
        for name in names:
            ref = next(c for c in self.containers[ref].contents if _name(self.child(c)) == name)
        return self.child(ref)

    def views_under(self, item: Container | View) -> list[View]:
        if isinstance(item, View):
            return [item]
        return [v for ref in item.contents for v in self.views_under(self.child(ref))]


def _name(item) -> str:
    return item.name


def read_blueprint(path: str | Path) -> Blueprint:
    """The blueprint stored in the ``.rrd`` at ``path`` (the last value of each field)."""
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    fields: dict[str, dict] = {}
    for chunk in reader.stream(store=reader.blueprints()[0]).to_chunks():
        entity = str(chunk.entity_path) if hasattr(chunk, "entity_path") else str(chunk).split("entity_path: ")[1].split()[0]
        for row in chunk.to_record_batch().to_pylist():
            fields.setdefault(entity, {}).update({k: v for k, v in row.items() if v is not None})
    views: dict[str, View] = {}
    containers: dict[str, Container] = {}
    for entity, f in fields.items():
        parts = entity.strip("/").split("/")
        if parts[0] == "view" and len(parts) == 2:
            ref = f"view/{parts[1]}"
            queries = fields.get(f"{entity}/ViewContents", {}).get("ViewContents:query") or ["$origin/**"]
            legend = fields.get(f"{entity}/PlotLegend", {}).get("PlotLegend:visible")
            views[ref] = View(f["ViewBlueprint:class_identifier"][0], (f.get("ViewBlueprint:display_name") or [""])[0],
                              f["ViewBlueprint:space_origin"][0], list(queries), None if legend is None else legend[0])
        elif parts[0] == "container":
            containers[f"container/{parts[1]}"] = Container(f["ContainerBlueprint:container_kind"][0],
                                                            (f.get("ContainerBlueprint:display_name") or [""])[0],
                                                            list(f.get("ContainerBlueprint:contents") or []))
    root = bytes(fields["/viewport"]["ViewportBlueprint:root_container"][0])
    panels = {p: fields[f"/{p}"][f"{'TimePanelBlueprint' if p == 'time_panel' else 'PanelBlueprint'}:state"][0]
              for p in ("blueprint_panel", "selection_panel", "time_panel") if f"/{p}" in fields}
    return Blueprint(f"container/{_uuid(root)}", containers, views, panels)


def _uuid(raw: bytes) -> str:
    h = raw.hex()
    return f"{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:]}"


def entities(path: str | Path) -> list[str]:
    """Every entity path of the recording in the ``.rrd`` at ``path`` (escaped form)."""
    from rerun.chunk import RrdReader

    return list(RrdReader(str(path)).store().schema().entity_paths())


def static_values(path: str | Path, entity: str, component: str) -> list:
    """The values of a static ``component`` (e.g. ``Points2D:labels``) logged at ``entity``
    (escaped path) in the ``.rrd`` at ``path``, every instance in order; [] when absent."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    chunks = RrdReader(str(path)).stream().filter(content=entity, is_static=True, components=component).to_chunks()
    if not chunks:
        return []
    column = pa.Table.from_batches([c.to_record_batch() for c in chunks]).column(component)
    return [value for row in column.to_pylist() if row is not None for value in row]


def packed(rgb) -> int:
    """A colour as Rerun stores it (``Color``: 0xRRGGBBAA, opaque)."""
    r, g, b = rgb
    return (r << 24) | (g << 16) | (b << 8) | 0xFF


def track_views(blueprint: Blueprint) -> list[View]:
    """The harness's 2-D track views (bench.recording.blueprint): one per trial tab with positions."""
    return [v for v in blueprint.views.values() if v.kind == "2D" and v.name == "track (north up)"]


def axes_of(path: str | Path, view: View, entities) -> tuple[int, list[str]]:
    """A track view's axes as the recording at ``path`` draws them in it: the number of line
    strips at ``{origin}/axes`` (the L, then a mark per tick) and the labels at
    ``{origin}/axes/labels`` (tick values, then the titles); (0, []) for what the view does
    not show (``entities``: the recording's, escaped)."""
    shown = set(view.shows(entities))
    lines, labels = f"{view.origin}/axes", f"{view.origin}/axes/labels"
    return (len(static_values(path, lines, "LineStrips2D:strips")) if lines in shown else 0,
            static_values(path, labels, "Points2D:labels") if labels in shown else [])
