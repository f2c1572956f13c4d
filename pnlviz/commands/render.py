"""``pnlviz render``: an overlay video of a clip, the pitch drawn through each frame's camera.

    pnlviz render --cameras cams.zip (--video clip.mp4 | --data DIR) --out overlay.mp4 [--fps 25]

Frames come from the video (decoded one at a time) or from a frame folder, in clip order (see
:func:`pnlviz.data.layout.clips`; a folder of several clips is rendered clip after clip); each is
drawn with the pitch of its camera (``camera_<stem>.json`` in the zip, any SoccerNet camera),
frames without a camera are written as they are with "no camera" in the corner. The output is
mp4 (OpenCV's mp4v codec) at the frames' size.
"""

from __future__ import annotations

import sys
from pathlib import Path
from pnlviz.commands.common import add_output_options, float_in


def add_render_parser(sub) -> None:
    p = sub.add_parser("render", help="overlay video: the pitch drawn through each frame's camera",
                       description="Write an mp4 of a clip's frames with the pitch model drawn through each "
                                   "frame's camera (e.g. from pnlviz calibrate --temporal).")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--video", type=Path, help="the clip as a video file")
    src.add_argument("--data", type=Path, help="the clip as a folder (or zip) of frames")
    p.add_argument("--cameras", required=True, type=Path, help="camera zip or folder (camera_<stem>.json)")
    p.add_argument("--out", required=True, type=Path, help="output video (.mp4)")
    p.add_argument("--fps", type=float_in(0.0, 1000.0, open_low=True), default=None, help="frames per second (default: the video's, else 25)")
    p.add_argument("--no-top-view", action="store_true",
                   help="no bird's-eye inset (the camera's footprint on the pitch, bottom right)")
    add_output_options(p)
    p.set_defaults(func=run_render)


def run_render(args) -> int:
    from pnlviz.commands.common import open_input_dataset, print_skipped
    from pnlviz.data import check_output
    from pnlviz.data.layout import clips
    from pnlviz.data.atomic import refuse_non_regular
    from pnlviz.data.cameras import read_cameras

    if args.out.suffix.lower() not in (".mp4", ".m4v", ".mov"):
        print(f"error: --out {args.out} must end in .mp4", file=sys.stderr)
        return 2
    check_output(args.out, inputs=[p for p in (args.video, args.cameras) if p is not None],
                 datasets=[args.data] if args.data is not None else [])
    if args.video is not None:
        from pnlviz.data.video import VideoDataset

        ds = VideoDataset(args.video)
        fps = args.fps or ds.fps or 25.0
    else:
        ds = open_input_dataset(args.data)
        fps = args.fps or 25.0
    cameras, problems = read_cameras(args.cameras, on_error=lambda line: None, splits=ds.splits)
    print_skipped(problems)
    stems = [s for members in clips([s for s in ds.stems if ds.frame(s).has_image]).values() for s in members]
    if not stems:
        print(f"{args.video or args.data}: no frames", file=sys.stderr)
        return 1
    tmp = args.out.with_name(f".{args.out.stem}.tmp{args.out.suffix}")
    drawn, skipped, wrote = _render_frames(args, ds, cameras, stems, fps, tmp)
    if wrote is None:
        return 2
    if not wrote:
        print(f"error: no frame could be read from {args.video or args.data}", file=sys.stderr)
        return 1
    if not tmp.is_file() or tmp.stat().st_size == 0:
        print(f"error: {args.out}: the video could not be written (full disk?)", file=sys.stderr)
        tmp.unlink(missing_ok=True)
        return 1
    refuse_non_regular(args.out)
    tmp.replace(args.out)
    print(f"wrote {args.out}: {len(stems) - len(skipped)} frames at {fps:g} fps, the pitch drawn on {drawn}")
    print_skipped(skipped, prefix="  skipped: ")
    return 0


def _render_frames(args, ds, cameras: dict, stems: list[str], fps: float, tmp) -> tuple[int, list[str], bool | None]:
    """The frames ``stems`` with the pitch of their camera drawn, written to the video ``tmp``:
    (frames with a camera, the frames that could not be read, whether a frame was written; None
    when no video can be written)."""
    import cv2
    from tqdm import tqdm

    from pnlviz.data import DataError
    from pnlviz.geometry.camera import Camera
    from pnlviz.viz import cv_text, draw_pitch, inset_top_view

    writer = None
    drawn = 0
    skipped: list[str] = []
    for stem in tqdm(stems, desc="render", unit="frame", disable=args.no_progress or None):
        try:
            img = ds.image(stem)
        except DataError as exc:
            skipped.append(str(exc))
            continue
        h, w = img.shape[:2]
        if writer is None:
            writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter.fourcc(*"mp4v"), float(fps), (w, h))
            if not writer.isOpened():
                print(f"error: OpenCV cannot write {args.out} (no mp4 encoder, or its folder cannot be written)",
                      file=sys.stderr)
                return drawn, skipped, None
            size = (w, h)
        if (w, h) != size:
            img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
        cam = cameras.get(stem)
        if cam is not None:
            camera = Camera.from_soccernet(cam, 960, 540)
            draw_pitch(img, camera, colour=(80, 255, 255), thickness=2)
            if not args.no_top_view:
                inset_top_view(img, camera)
            drawn += 1
        else:
            cv2.putText(img, cv_text("no camera"), (12, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 255), 2, cv2.LINE_AA)
        writer.write(img)
    if writer is not None:
        writer.release()
    return drawn, skipped, writer is not None
