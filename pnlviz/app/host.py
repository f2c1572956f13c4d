"""What the session's parts are given by the session (no GUI here): :class:`FrameHost`, and
what a tab's parts are given by their tab: :class:`TabHandle`.

:class:`pnlviz.app.state.AppState` creates its parts (the frames' summaries and background pass,
:class:`pnlviz.app.triage.Triage`; the clips' shot models, :class:`pnlviz.app.shots.ClipShots`) and
hands each the few things it uses, as one typed value: the frames, their reader and views, the
one door through which a frame's edit record changes, and the notice that a frame changed. A
part never holds the session itself and never reaches into it. A tab's parts are given, the same
way, the few things of their tab they use (:class:`TabHandle`: which frame it shows, with which
settings; going to another frame; drawing it again; a notice), not the tab.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, TypeVar

if TYPE_CHECKING:
    from pnlviz.data.edits import EditsStore
    from pnlviz.field.model import FieldModel
    from pnlviz.pipeline import FrameReader, FrameView, Settings

__all__ = ["FrameHost", "Part", "TabHandle", "TabPart", "Write"]

T = TypeVar("T")

#: the one door for a change to a frame's edit record: ``write(stem, change, *, corrected=True,
#: settings=None, merge=None, snapshot=None) -> bool`` (:meth:`pnlviz.app.state.AppState.write`)
Write = Callable[..., bool]


@dataclass(frozen=True)
class FrameHost:
    """The session's frames as its parts see them.

    ``stems``: the frames in dataset order; ``reader``: where their inputs are read
    (:class:`pnlviz.pipeline.FrameReader`) and its edits folder ``edits``; ``model``: the pitch;
    ``default_settings``: the settings frames are seen with unless a tab says otherwise;
    ``view(stem, settings, keep=True)``: a frame's view, cached; ``cached_view(stem, settings)``:
    the view if it is computed already (None otherwise); ``needs_detection(stem)``: whether the
    frame still waits for the detector; ``write``: the one door for edits (:data:`Write`);
    ``notify(stem)``: tell every tab that the frame shows something else now.
    """

    stems: Sequence[str]
    reader: FrameReader
    edits: EditsStore
    model: FieldModel
    default_settings: Settings
    view: Callable[..., FrameView]
    cached_view: Callable[..., FrameView | None]
    needs_detection: Callable[[str], bool]
    write: Write
    notify: Callable[[str], Any]


@dataclass(frozen=True)
class TabHandle:
    """One tab as its parts see it: ``index()`` the dataset index of the frame it shows,
    ``settings()`` the settings it shows it with, ``goto(index)`` go to another frame, ``show()``
    draw the frame again, ``notify(title, body, error=True)`` a notice in the tab."""

    index: Callable[[], int]
    settings: Callable[[], Settings]
    goto: Callable[[int], Any]
    show: Callable[[], Any]
    notify: Callable[..., None]


class Part(Generic[T]):
    """An attribute of a :class:`TabPart` that reads one of the tab's parts made after it:
    ``parts()[index]`` (``painter: ClassVar[Part[Painter]] = Part(0)``: typed as the part it is)."""

    def __init__(self, index: int):
        self.index = index

    def __get__(self, obj: Any, owner: Any = None) -> T:
        if obj is None:  # read on the class (a dataclass looking for defaults): the descriptor
            return self  # type: ignore[return-value]
        return obj.parts()[self.index]


@dataclass(frozen=True)
class TabPart:
    """The base of what a tab's part is given (:class:`pnlviz.app.editing.EditorTab`,
    :class:`pnlviz.app.drawing.PainterTab`): the session's ``state`` and the tab's ``handle``,
    with the frame the tab shows and its settings read from them."""

    state: Any
    handle: TabHandle

    @property
    def stem(self) -> str:
        """The stem of the frame the tab shows."""
        return self.state.stems[self.handle.index()]

    @property
    def settings(self) -> Settings:
        """The settings the tab shows its frame with."""
        return self.handle.settings()

    def show(self) -> Any:
        """The tab's frame drawn again (as the tab decides: it may compute its view first)."""
        return self.handle.show()
