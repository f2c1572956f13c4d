"""A tab's clip timeline (video datasets): the frames of the clip it is in, each one's error in
the strip under the clip slider, jumps to the worst frames, and playing the clip.

What a clip is and the strip's pixels are :mod:`pnlviz.app.timeline`'s (no GUI there); this part
follows the tab's frame through them and plays on the tab's queue.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pnlviz.app.cards import clip_text
from pnlviz.app.handles import update_changed
from pnlviz.app.host import TabHandle
from pnlviz.app.timeline import strip_image, worst_frames

if TYPE_CHECKING:
    from pnlviz.app.shots import ClipShots
    from pnlviz.app.tabqueue import TabQueue

PLAY_INTERVAL = 0.2  # seconds between frames while a clip plays


@dataclass(frozen=True)
class ClipWidgets:
    """The panel's clip line (markdown), error strip (image) and slider."""

    text: Any
    strip: Any
    slider: Any


class ClipPlayer:
    """The clip of one tab: ``tab`` its frame and moves (:class:`pnlviz.app.host.TabHandle`),
    ``clips`` ``{clip: [dataset indices in frame order]}`` of the dataset, ``stems`` the
    dataset's frames, ``shots`` the clips' shot models (:class:`pnlviz.app.shots.ClipShots`),
    ``summaries(stem, settings)`` a frame's summary when known
    (:meth:`pnlviz.app.triage.Triage.lookup`), ``queue`` the tab's queue; ``widgets``: the
    panel's clip widgets, once the panel is made (None: nothing shown)."""

    def __init__(self, tab: TabHandle, clips: dict[str, list[int]], *, stems: Sequence[str], shots: ClipShots,
                 summaries: Callable[[str, Any], Any], queue: TabQueue):
        self.tab, self.clips = tab, clips
        self.stems, self.shots, self.summaries, self.queue = stems, shots, summaries, queue
        self.widgets: ClipWidgets | None = None
        self.clip_of = {i: name for name, members in clips.items() for i in members}
        self.playing = False
        self._worst = 0  # how far "next worst" has gone down the current clip's list
        #: a clip frame shows its shot's camera (:mod:`pnlviz.app.shots`); off: its own camera
        self.shot_model = True

    def members(self) -> list[int]:
        """Dataset indices of the frames of the tab's clip, in frame order ([] outside a clip, and
        in a named clip whose frames turned out to be unrelated pictures)."""
        name = self.clip_of.get(self.tab.index())
        if name is None or self.shots.unrelated(name):
            return []
        return self.clips.get(name, [])

    def _shot_strip(self):
        """(errors, cuts, keyframes) of the clip under its shot model, None without one (yet)."""
        if not self.shot_model or not self.members():
            return None
        return self.shots.strip(self._stem(), self.tab.settings())

    def errors(self) -> list[float]:
        """Each clip frame's error under its shot model when it has one (its observations' median
        distance to the shot's camera); else its own (the median residual, ``inf`` without a
        camera, NaN not calibrated yet), from the frames' summaries (:meth:`pnlviz.app.triage.Triage.lookup`):
        a lookup per clip frame, not a pass over every frame."""
        shot = self._shot_strip()
        if shot is not None:
            return shot[0]
        settings = self.tab.settings()
        summaries = [self.summaries(self.stems[i], settings) for i in self.members()]
        return [float("nan") if s is None else s.error for s in summaries]

    def show(self) -> None:
        """The clip line, the strip and the clip slider of the panel (a dataset without clips
        has none)."""
        w = self.widgets
        if w is None:
            return
        members = self.members()
        if not members:
            update_changed(w.text, content="this frame is not part of a clip")
            return
        index = self.tab.index()
        pos = members.index(index)
        shot = self._shot_strip()
        errors = shot[0] if shot is not None else self.errors()
        text = clip_text(self.clip_of[index], pos, errors, self.playing)
        update_changed(w.text, content=text + self._shot_text(pos, shot))
        strip = strip_image(errors, pos, cuts=shot[1] if shot else (), keyframes=shot[2] if shot else ())
        if w.strip.image is None or not np.array_equal(w.strip.image, strip):
            w.strip.image = strip
        w.slider.max = max(2, len(members))
        self.queue.set_value(w.slider, pos + 1)

    def slider_moved(self, value) -> None:
        members = self.members()
        if not members:
            return
        try:
            pos = int(value) - 1
        except (TypeError, ValueError, OverflowError):
            pos = 0
        pos = int(np.clip(pos, 0, len(members) - 1))
        if members[pos] != self.tab.index():
            self.tab.goto(members[pos])

    def jump_worst(self, restart: bool = False) -> None:
        """To the clip's worst frame (``restart``), else the next worse one after the last jump."""
        members = self.members()
        ranked = worst_frames(self.errors())
        if not ranked:
            self.tab.notify("nothing yet", "no frame of this clip is calibrated yet", error=False)
            return
        self._worst = 0 if restart else (self._worst + 1) % len(ranked)
        self.tab.goto(members[ranked[self._worst]])

    def _shot_text(self, pos: int, shot) -> str:
        if not self.shot_model:
            return "  \nshot model **off**: the frame's own camera"
        if shot is None:
            return "  \nshot model: solving the clip's shots..."
        starts = [0, *shot[1]]
        k = sum(1 for s in starts if s <= pos)
        n = len(shot[2])
        return f"  \nshot {k} of {len(starts)} · {n} keyframe{'' if n == 1 else 's'} (corrected by hand)"

    def _stem(self) -> str:
        return self.stems[self.tab.index()]

    # ------------------------------------------------------------------ the shot model
    def set_shot_model(self, on) -> None:
        """Show the shot's camera (``on``) or the frame's own camera, to compare."""
        self.shot_model = bool(on)
        self.tab.show()

    def accept_shot(self) -> None:
        """Review the frame's whole shot at once: every frame accepted with what its shot shows."""
        if not self.members():
            return
        done = self.shots.accept(self._stem(), self.tab.settings())
        self.tab.notify("shot accepted", f"{len(done)} frames reviewed ({done[0]} .. {done[-1]})" if done
                        else "nothing to accept", error=False)
        self.tab.show()

    def toggle_cut(self) -> None:
        """A cut before this frame added by hand, or removed when there is one."""
        cut = self.shots.toggle_cut(self._stem(), self.tab.settings()) if self.members() else None
        if cut is None:
            self.tab.notify("no cut", "a cut goes before a frame of a clip other than its first", error=False)
        else:
            self.tab.notify("cut added" if cut else "cut removed", f"before {self._stem()}", error=False)
        self.tab.show()

    # ------------------------------------------------------------------ playing
    def play(self) -> None:
        """Step through the clip, about 5 frames a second, until its end or a pause (navigating
        meanwhile moves where it plays from)."""
        if self.playing or not self.members():
            return
        self.playing = True
        threading.Thread(target=self._loop, name="pnlviz-play", daemon=True).start()

    def pause(self) -> None:
        self.playing = False
        self.show()

    def toggle(self) -> None:
        self.pause() if self.playing else self.play()

    def advance(self) -> None:
        """One step of the playing clip: the next frame, or at the clip's end (or paused), stop."""
        members, index = self.members(), self.tab.index()
        if not members or index == members[-1] or not self.playing:
            self.playing = False
            self.show()
        else:
            self.tab.goto(members[members.index(index) + 1])

    def _loop(self) -> None:
        while self.playing and not self.queue.closed:
            t0 = time.monotonic()
            done = threading.Event()

            def step(done: threading.Event = done) -> None:
                try:
                    self.advance()
                finally:
                    done.set()

            self.queue.enqueue(step)
            done.wait(5.0)
            time.sleep(max(0.0, PLAY_INTERVAL - (time.monotonic() - t0)))


__all__ = ["PLAY_INTERVAL", "ClipPlayer", "ClipWidgets"]
