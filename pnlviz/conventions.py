"""Conventions every room of pnlviz shares, defined once."""

#: SoccerNet evaluates cameras at this image size (W, H); cameras are written at it, and frames
#: without an image are calibrated at it unless told otherwise
EVAL_SIZE: tuple[int, int] = (960, 540)
EVAL_WIDTH, EVAL_HEIGHT = EVAL_SIZE
#: the PnL weight of lines against points (the paper's 0.6)
DEFAULT_ALPHA = 0.6
