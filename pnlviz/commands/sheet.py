"""``pnlviz sheet``: a contact sheet of frames with their annotations and the pitch reprojected
through their cameras."""

from __future__ import annotations

import sys
from pathlib import Path

from pnlviz.commands.common import add_output_options, int_at_least, open_input_dataset, print_skipped


def add_sheet_parser(sub) -> None:
    p = sub.add_parser("sheet", help="contact sheet of frames with annotations and the camera's pitch",
                       description="Draw the first N frames of a dataset with their annotated lines and, "
                                   "when a camera is known, the pitch model reprojected through it.")
    p.add_argument("--data", required=True, type=Path, help="dataset folder or zip")
    p.add_argument("--out", required=True, type=Path, help="output image (.png or .jpg)")
    p.add_argument("--cameras", type=Path, help="camera zip (default: the dataset's cameras/ folder)")
    p.add_argument("-n", type=int_at_least(1), default=12, help="number of frames (default 12)")
    p.add_argument("--columns", type=int_at_least(1, 64), default=4)
    p.add_argument("--tile-width", type=int_at_least(16, 4096), default=480)
    p.add_argument("--no-annotation", action="store_true", help="draw only the camera's pitch")
    add_output_options(p)
    p.set_defaults(func=_run_sheet)


SHEET_FORMATS = (".png", ".jpg", ".jpeg")


def _run_sheet(args) -> int:
    import cv2

    from pnlviz.data import DataError, OutputError, atomic_write_bytes, check_output, read_camera_zip
    from pnlviz.geometry import Camera
    from pnlviz.viz import blank_canvas, caption, contact_sheet, draw_annotation, draw_pitch

    ext = args.out.suffix.lower()
    if ext not in SHEET_FORMATS:
        raise OutputError(f"--out {args.out}", "the sheet must be a .png or .jpg file")
    check_output(args.out, inputs=[args.cameras], datasets=[args.data])
    ds = open_input_dataset(args.data)
    cams = (read_camera_zip(args.cameras, on_error=lambda e: print_skipped([e]), splits=ds.splits)
            if args.cameras else {})
    tiles = []
    for stem in ds.stems[: args.n]:
        frame = ds.frame(stem)
        try:
            img = ds.image(stem) if frame.has_image else blank_canvas()
            cam_dict = cams.get(stem) or ds.camera_dict(stem)
            if cam_dict is not None:
                draw_pitch(img, Camera.from_soccernet(cam_dict), thickness=2)
            if frame.has_annotation and not args.no_annotation:
                draw_annotation(img, ds.annotation(stem), radius=2)
            text = stem if cam_dict is None else f"{stem}  {cam_dict.get('synth', {}).get('kind', '')}".strip()
            tiles.append(caption(img, text))
        except DataError as exc:
            print_skipped([exc])
    if not tiles:
        print("nothing to draw", file=sys.stderr)
        return 1
    sheet = contact_sheet(tiles, columns=args.columns, tile_width=args.tile_width)
    ok, encoded = cv2.imencode(ext, sheet)  # encoded here, written by Python: any file name works
    if not ok:
        print(f"{args.out}: cannot encode the sheet as {ext}", file=sys.stderr)
        return 1
    atomic_write_bytes(args.out, encoded.tobytes())
    print(f"wrote {args.out} ({len(tiles)} frames)")
    return 0
