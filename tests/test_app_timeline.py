"""The clip timeline (issue #14): a video dataset's frames form clips; the strip shows each frame's
error; the worst frames are one click away; play steps through the clip and stops at its end."""

import time

import numpy as np
import pytest

from pnlviz.app.timeline import clip_index, frame_error, strip_image, worst_frames


def test_clips_are_named_runs_of_frames_and_plain_numbers_are_not():
    stems = ["b-IMG_2", "a-IMG_10", "a-IMG_9", "b-IMG_1", "b-IMG_3", "a-IMG_11", "00001", "00002", "00003"]
    clips = clip_index(stems)
    assert list(clips) == ["a", "b"]
    assert [stems[i] for i in clips["a"]] == ["a-IMG_9", "a-IMG_10", "a-IMG_11"]
    assert clip_index(["x-IMG_1", "x-IMG_2"]) == {}  # too short to be a clip
    # named picks of separate pictures (the bundled sample's wc14_3, wc14_8, ...) are no clip
    assert clip_index(["wc14_3", "wc14_8", "wc14_11", "wc14_17", "sn22_00004", "sn22_00097", "sn22_00187"]) == {}
    assert list(clip_index(["v-IMG_1", "v-IMG_2", "v-IMG_4", "v-IMG_5"])) == ["v"]  # a dropped frame is fine


def test_the_strip_colours_each_frame_by_its_error_and_frames_the_current_one():
    errors = [0.0, 2.0, 10.0, float("inf"), float("nan")]
    img = strip_image(errors, current=1, width=100, height=20)
    mid = img[10]
    centre = [mid[10], mid[30], mid[50], mid[70], mid[90]]
    assert centre[0][1] > 200 and centre[0][0] < 10  # green: 0 px
    assert centre[2][0] > 200 and centre[2][1] < 10  # red: 10 px and more
    assert tuple(centre[3]) == (120, 0, 0) and tuple(centre[4]) == (90, 90, 90)  # no camera / not yet
    assert (img[0, 20:40] == 255).all() and not (img[0, 60:80] == 255).all()  # the current frame framed
    assert worst_frames(errors) == [3, 2, 1, 0] and worst_frames(errors, 2) == [3, 2]
    assert np.isnan(frame_error(None))


@pytest.fixture()
def clip_data(tmp_path):
    from pnlviz.synth import generate

    d = tmp_path / "clip"
    generate(d, 8, 3, size=(320, 180), clip=True, progress=False)
    generate(d, 2, 1, size=(320, 180), progress=False, force=True)  # two plain frames beside the clip
    return d


def test_the_app_shows_the_clip_timeline_jumps_to_the_worst_and_plays(clip_data, serve):
    from pnlviz.app.playback import PLAY_INTERVAL

    app = serve(clip_data)
    st = app.state
    tab = app.session()
    first = st.find("clip3-IMG_0001")
    tab.goto(first)
    assert tab.clip.members()[0] == first and len(tab.clip.members()) == 8
    for i in tab.clip.members():  # calibrate the clip (the background worker would, in time)
        st.view(st.stems[i], tab.settings)
    # its shot model too (built in the background otherwise: the errors change when it lands)
    st.shots.build(tab.clip.clip_of[first], tab.settings)
    tab.show()
    p = tab.panels
    assert "frame 1 of 8" in p.clip_text.content and "error" in p.clip_text.content
    assert p.clip_strip.image.shape == (26, 320, 3) and p.clip_slider.value == 1
    errors = tab.clip.errors()
    assert not any(np.isnan(errors))
    tab.clip.jump_worst(restart=True)
    assert tab.index == tab.clip.members()[int(np.argmax(errors))]
    tab.clip.jump_worst()
    second = sorted(range(8), key=lambda i: (-errors[i], i))[1]
    assert tab.index == tab.clip.members()[second]
    tab.clip.slider_moved(3)
    assert tab.stem == "clip3-IMG_0003" and "frame 3 of 8" in p.clip_text.content
    tab.clip.play()
    deadline = time.monotonic() + 30 * PLAY_INTERVAL + 20
    while tab.clip.playing and time.monotonic() < deadline:
        time.sleep(0.05)
    tab.flush()
    assert not tab.clip.playing and tab.stem == "clip3-IMG_0008"  # played to the end and stopped
    tab.goto(st.find("00000"))
    assert "not part of a clip" in p.clip_text.content
    tab.clip.play()
    assert not tab.clip.playing  # nothing to play outside a clip


def test_a_dataset_without_clips_has_no_clip_panel(tmp_path, serve):
    from pnlviz.synth import generate

    generate(tmp_path / "frames", 3, 2, size=(320, 180), progress=False)
    app = serve(tmp_path / "frames")
    tab = app.session()
    assert tab.clip.clips == {} and tab.panels.clip_text is None
    tab.show()


def test_no_part_of_a_tab_holds_the_session(tmp_path, serve):
    """The tab's parts get what they use (a TabHandle, an EditorTab, a PainterTab, the panel's
    widgets' needs), never the session: no attribute of a part, nor of what a part was given, is
    the session."""
    import dataclasses

    from pnlviz import EXAMPLES_DIR

    app = serve(EXAMPLES_DIR / "sample", edits=tmp_path / "edits")
    tab = app.session()
    parts = [tab.editor, tab.painter, tab.panels, tab.clip, tab.view_control, tab.workspace, tab.scene3d,
             tab.queue, tab.guard, tab.editor.trail]
    given = [v for part in parts for v in vars(part).values()]
    given += [v for g in list(given) if dataclasses.is_dataclass(g) and not isinstance(g, type)
              for v in vars(g).values()]
    assert given and not any(v is tab for v in given)
    # and each still reaches what it uses: the frame shown, through its handle
    assert tab.editor.tab.stem == tab.painter.tab.stem == tab.stem
    assert tab.clip.tab.index() == tab.index


def _strip_by_frames(errors, width, height, scale):
    """The strip's bands painted frame by frame, later frames over earlier ones (the reference)."""
    img = np.zeros((height, width, 3), np.uint8)
    edges = np.linspace(0, width, len(errors) + 1).round().astype(int)
    for i, v in enumerate(errors):
        if np.isnan(v):
            colour = (90, 90, 90)
        elif np.isinf(v):
            colour = (120, 0, 0)
        else:
            t = min(max(v / scale, 0.0), 1.0)
            colour = (int(255 * min(1.0, 2 * t)), int(255 * min(1.0, 2 * (1 - t))), 40)
        img[3:height - 3, edges[i]:max(edges[i + 1], edges[i] + 1)] = colour
    return img


@pytest.mark.parametrize("n", [1, 7, 250, 320, 333, 1000])
def test_the_strip_paints_every_frame_as_a_band_and_the_last_of_those_sharing_a_column(n):
    from pnlviz.app.timeline import STRIP_SCALE_PX

    rng = np.random.default_rng(n)
    errors = rng.uniform(-1.0, 2.5 * STRIP_SCALE_PX, n)
    errors[rng.random(n) < 0.1] = np.inf
    errors[rng.random(n) < 0.1] = np.nan
    errors[:3] = [0.0, STRIP_SCALE_PX / 2, STRIP_SCALE_PX][:n]
    img = strip_image(errors, None, width=320, height=26)
    assert np.array_equal(img, _strip_by_frames(errors, 320, 26, STRIP_SCALE_PX))
    if n == 1000:  # three frames or more to a column: the column shows the last of them
        edges = np.linspace(0, 320, n + 1).round().astype(int)
        last = max(i for i in range(n) if edges[i] <= 100)
        assert np.array_equal(img[10, 100], _strip_by_frames(errors[last:last + 1], 1, 26, STRIP_SCALE_PX)[10, 0])
