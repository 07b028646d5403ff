"""``camera detect`` and ``diagnose camera --images``: corners found by OpenCV in photographs.

References the code did not compute: chessboards rendered here by area sampling through a
known homography (each corner's true pixel is the homography applied to its board position),
and OpenCV's own sample photographs (tests/data/camera/opencv_left, README there).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from montecarlo.camera_calibration import detect as dt  # noqa: E402
from montecarlo.cli import main  # noqa: E402
from montecarlo.errors import InputError  # noqa: E402
from montecarlo.io.camera_csv import read_camera_csv  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PUBLIC = ROOT / "tests" / "data" / "camera" / "opencv_left"
SS = 8
"""Samples per pixel and axis of the rendering: an edge is placed to 1/SS px in each pixel,
so a corner fitted to many edge pixels is known to better than TOL."""
TOL = 1.0 / SS
SQUARE = 20.0
"""[mm]."""


def homography(quad, cols, rows):
    """Board [mm] -> image pixel centres [px]: the outer corners of the squares to ``quad``
    (top-left, top-right, bottom-right, bottom-left)."""
    w, h = (cols + 1) * SQUARE, (rows + 1) * SQUARE
    src = np.float32([[-SQUARE, -SQUARE], [w - SQUARE, -SQUARE], [w - SQUARE, h - SQUARE],
                      [-SQUARE, h - SQUARE]])
    return cv2.getPerspectiveTransform(src, np.float32(quad)).astype(float)


def render(cols, rows, H, size=(320, 240), margin=0.6):
    """A grey image of a chessboard of ``cols x rows`` inner corners (square (i, j) dark when
    i + j is even: the first inner square dark), on a white border ``margin`` squares wide,
    on a mid-grey background; every pixel the mean of SS x SS samples (area sampling), then
    blurred by a Gaussian of 1 px (a lens's)."""
    w, h = size
    a = ((np.arange(w * SS) + 0.5) / SS - 0.5).astype(np.float32)
    b = ((np.arange(h * SS) + 0.5) / SS - 0.5).astype(np.float32)
    inv = np.linalg.inv(H).astype(np.float32)
    den = inv[2, 0] * a[None, :] + inv[2, 1] * b[:, None] + inv[2, 2]
    # in squares from the board's edge
    x = (inv[0, 0] * a[None, :] + inv[0, 1] * b[:, None] + inv[0, 2]) / den / SQUARE + 1.0
    y = (inv[1, 0] * a[None, :] + inv[1, 1] * b[:, None] + inv[1, 2]) / den / SQUARE + 1.0
    i, j = np.floor(x), np.floor(y)
    board = (i >= 0) & (i <= cols) & (j >= 0) & (j <= rows)
    border = (x > -margin) & (x < cols + 1 + margin) & (y > -margin) & (y < rows + 1 + margin)
    value = np.where(border, np.float32(235.0), np.float32(128.0))
    value = np.where(board & ((i + j) % 2 == 0), np.float32(25.0), value)
    value = value.reshape(h, SS, w, SS).mean(axis=(1, 3))
    return np.round(cv2.GaussianBlur(value, (0, 0), 1.0)).astype(np.uint8)


def truth(board, H):
    xy = board.model_points()
    p = H @ np.column_stack([xy, np.ones(len(xy))]).T
    return (p[:2] / p[2]).T


QUAD = [(52, 38), (262, 52), (250, 205), (60, 188)]


@pytest.fixture(scope="module")
def view():
    board = dt.Board(7, 4, SQUARE)
    H = homography(QUAD, 7, 4)
    return board, render(7, 4, H), truth(board, H)


def test_corners_lie_where_the_homography_puts_them(view):
    board, image, true = view
    ids, pixels, by_colour = dt.find_chessboard(image, board)
    assert by_colour and list(ids) == list(range(board.n))
    error = np.hypot(*(pixels - true).T)
    assert error.max() < TOL, error.max()


@pytest.mark.parametrize("turns", [1, 2, 3])
def test_a_turned_image_gives_each_corner_the_same_id(view, turns):
    """Turning the image by 90°, 180°, 270° (np.rot90, anticlockwise): id k is still the
    corner the homography puts there, turned."""
    board, image, true = view
    w = image.shape[1]
    h = image.shape[0]
    turned = np.ascontiguousarray(np.rot90(image, turns))
    u, v = true.T
    for _ in range(turns):  # one anticlockwise turn: (u, v) -> (v, width - 1 - u)
        u, v = v, w - 1 - u
        w, h = h, w
    _, pixels, by_colour = dt.find_chessboard(turned, board)
    assert by_colour
    assert np.hypot(*(pixels - np.column_stack([u, v])).T).max() < TOL


@pytest.mark.parametrize("listing", ["reversed", "mirrored", "mirrored and reversed"])
def test_any_listing_of_the_grid_is_put_in_the_board_order(view, listing):
    """OpenCV may start at any corner and go either way: every listing comes back in order."""
    board, image, true = view
    grid = true.reshape(board.rows, board.cols, 2)
    given = {"reversed": grid[::-1, ::-1], "mirrored": grid[:, ::-1],
             "mirrored and reversed": grid[::-1, :]}[listing]
    ordered, by_colour = dt.order_grid(image, given, board)
    assert by_colour and np.array_equal(ordered, grid)


def test_a_symmetric_board_is_ordered_by_the_image_as_stated():
    """6 x 4 inner corners (7 x 5 squares) looks the same turned by 180°: id 0 is the grid
    corner nearest the image's top-left, in the image and in the image turned by 180°."""
    board = dt.Board(6, 4, SQUARE)
    assert board.symmetric
    H = homography(QUAD, 6, 4)
    image = render(6, 4, H)
    for img in (image, np.ascontiguousarray(image[::-1, ::-1])):
        _, pixels, by_colour = dt.find_chessboard(img, board)
        assert not by_colour
        corners = pixels[[0, board.cols - 1, board.n - board.cols, board.n - 1]]
        assert np.argmin(corners.sum(axis=1)) == 0


def test_a_partial_chessboard_is_not_found():
    H = homography([(-40, 38), (170, 52), (158, 205), (-32, 188)], 7, 4)
    assert dt.find_chessboard(render(7, 4, H), dt.Board(7, 4, SQUARE)) is None


def _charuco_view(board, quad, size=(480, 360)):
    """A ChArUco board drawn by OpenCV at 10 px/mm, warped by a known homography onto an
    SS-times finer image and area-averaged down; its true corners."""
    cb = dt.charuco_board(board)
    sq = (board.cols + 1, board.rows + 1)
    scale = 10.0 / SQUARE * 20  # px per mm of the drawn board
    drawn = cb.generateImage((int(sq[0] * board.square * scale),
                              int(sq[1] * board.square * scale)), marginSize=0, borderBits=1)
    h_mm = cv2.getPerspectiveTransform(
        np.float32([[0, 0], [sq[0] * board.square, 0], [sq[0] * board.square,
                    sq[1] * board.square], [0, sq[1] * board.square]]), np.float32(quad))
    # drawn pixel centres -> mm -> fine output pixel centres
    to_mm = np.array([[1 / scale, 0, 0.5 / scale], [0, 1 / scale, 0.5 / scale], [0, 0, 1]])
    fine = np.array([[SS, 0, (SS - 1) / 2], [0, SS, (SS - 1) / 2], [0, 0, 1]])
    warped = cv2.warpPerspective(drawn, fine @ h_mm @ to_mm, (size[0] * SS, size[1] * SS),
                                 flags=cv2.INTER_LINEAR, borderValue=128)
    image = cv2.resize(warped, size, interpolation=cv2.INTER_AREA)
    xy = np.asarray(cb.getChessboardCorners(), float)[:, :2]
    p = h_mm @ np.column_stack([xy, np.ones(len(xy))]).T
    return image, (p[:2] / p[2]).T


def test_charuco_corners_keep_their_ids_on_a_partial_board():
    board = dt.Board(5, 4, SQUARE, "DICT_4X4_50", 15.0)
    quad = [(60, 50), (420, 70), (400, 320), (80, 300)]
    image, true = _charuco_view(board, quad)
    detector = cv2.aruco.CharucoDetector(dt.charuco_board(board))
    ids, pixels, _ = dt.find_charuco(image, board, detector)
    assert list(ids) == list(range(board.n))
    assert np.hypot(*(pixels - true[ids]).T).max() < 2 * TOL
    part = image.copy()
    part[:, 250:] = 128  # the right part of the board hidden
    ids, pixels, _ = dt.find_charuco(part, board, detector)
    assert 4 <= len(ids) < board.n
    assert np.hypot(*(pixels - true[ids]).T).max() < 2 * TOL
    assert np.all(true[ids, 0] < 250)


# ----------------------------------------------------------------------------------- the CLI


@pytest.fixture(scope="module")
def three_views(tmp_path_factory):
    """Three rendered views of a 7 x 4 board (one turned by 180°), written as PNG files."""
    d = tmp_path_factory.mktemp("views")
    quads = [QUAD, [(40, 60), (250, 30), (280, 200), (70, 215)],
             [(70, 40), (270, 70), (240, 220), (50, 180)]]
    paths, truths = [], []
    board = dt.Board(7, 4, SQUARE)
    for k, quad in enumerate(quads):
        H = homography(quad, 7, 4)
        image, true = render(7, 4, H), truth(board, H)
        if k == 2:
            image = np.ascontiguousarray(image[::-1, ::-1])
            true = np.array([image.shape[1] - 1, image.shape[0] - 1]) - true
        path = d / f"view{k + 1}.png"
        cv2.imwrite(str(path), image)
        paths.append(path)
        truths.append(true)
    return paths, truths


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_detect_writes_what_diagnose_camera_reads(three_views, tmp_path, capsys):
    paths, truths = three_views
    code, out, err = _run(capsys, "camera", "detect", *paths, "--board", "7x4", "--square-mm",
                          "20", "--out", tmp_path / "det")
    assert code == 0, err
    assert "found in 3 of 3 images (320x240 px), 84 corners" in out
    assert "board not found (left out): none" in out
    data = read_camera_csv(tmp_path / "det" / "model.csv", tmp_path / "det" / "views.csv")
    assert data.views == ("view1", "view2", "view3") and data.unit == "mm"
    for v, true in enumerate(truths):
        mine = data.view == v
        assert [int(k) for k in np.array(data.point_id)[mine]] == list(range(28))
        assert np.hypot(*(data.pixels[mine] - true).T).max() < TOL
    # id 27 (col 6, row 3) sits at X = 120 mm, Y = 60 mm [m in memory]
    assert tuple(data.points[27]) == pytest.approx((0.12, 0.06))
    assert (tmp_path / "det" / "contact_sheet.png").stat().st_size > 10_000


def test_images_without_the_board_are_listed(three_views, tmp_path, capsys):
    paths, _ = three_views
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((240, 320), 128, np.uint8))
    code, out, err = _run(capsys, "camera", "detect", *paths, blank, "--board", "7x4",
                          "--square-mm", "20", "--out", tmp_path / "det")
    assert code == 0, err
    assert "found in 3 of 4 images" in out
    assert f"board not found (left out): {blank}" in out


def _refused(capsys, *argv):
    code, out, err = _run(capsys, *argv)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def test_bad_images_and_boards_are_refused_in_one_line(three_views, tmp_path, capsys):
    paths, _ = three_views
    board = ("--board", "7x4", "--square-mm", "20", "--out", tmp_path / "det")
    text = tmp_path / "notes.jpg"
    text.write_text("not an image")
    line = _refused(capsys, "camera", "detect", *paths, text, *board)
    assert str(text) in line and "not an image" in line
    line = _refused(capsys, "camera", "detect", *paths, tmp_path / "absent.png", *board)
    assert "absent.png" in line and "no such image file" in line
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((100, 120), np.uint8))
    line = _refused(capsys, "camera", "detect", *paths, small, *board)
    assert "small.png: 120x100 px" in line and "320x240 px" in line
    line = _refused(capsys, "camera", "detect", *paths, "--board", "6x4", "--square-mm", "20",
                    "--out", tmp_path / "det")
    assert "--board 6x4" in line and "no 6x4 chessboard" in line and "any of the 3" in line
    line = _refused(capsys, "camera", "detect", *paths[:2], "--board", "7x4", "--square-mm",
                    "20", "--out", tmp_path / "det")
    assert "found in 2 of 2" in line and "at least 3" in line
    line = _refused(capsys, "camera", "detect", *paths, "--board", "7by4", "--square-mm", "20",
                    "--out", tmp_path / "det")
    assert "'7by4'" in line
    line = _refused(capsys, "camera", "detect", "--board", "7x4", "--square-mm", "20",
                    "--out", tmp_path / "det")
    assert "images" in line
    line = _refused(capsys, "camera", "detect", *paths, *board, "--charuco", "DICT_NOPE",
                    "--marker-mm", "10")
    assert "'DICT_NOPE'" in line
    assert not (tmp_path / "det").exists()


def test_diagnose_camera_needs_one_source(three_views, tmp_path, capsys):
    paths, _ = three_views
    line = _refused(capsys, "diagnose", "camera", "--pixel-sigma-px", "0.1")
    assert "MODEL.csv VIEWS.csv, or --images" in line
    line = _refused(capsys, "diagnose", "camera", "--images", *paths, "--pixel-sigma-px", "0.1")
    assert "--board: needed with --images" in line
    line = _refused(capsys, "diagnose", "camera", "m.csv", "v.csv", "--board", "7x4",
                    "--pixel-sigma-px", "0.1")
    assert "--board: only with --images" in line


def test_opencv_is_needed_only_for_images(monkeypatch):
    """The package imports without OpenCV; asking for images then says how to install it."""
    monkeypatch.setitem(sys.modules, "cv2", None)
    with pytest.raises(InputError, match=r"pip install 'montecarlo\[camera\]'"):
        dt.read_grey(PUBLIC / "left01.jpg")


def test_the_public_photographs_first_three():
    """OpenCV's sample photographs: the 9 x 6 board in each of the first three; its first
    inner square (ids 0, 1, 10, 9) dark and the last (ids 43, 44, 53, 52) light, sampled at
    their centres; every corner within 0.3 px of OpenCV's classic detector refined by
    cornerSubPix."""
    paths = sorted(PUBLIC.glob("left0[123].jpg"))
    found, missing, size = dt.detect(paths, dt.Board(9, 6, 25.0))
    assert size == (640, 480) and not missing and len(found) == 3
    for d in found:
        image = dt.read_grey(d.path)
        assert d.by_colour and len(d.ids) == 54
        first, last = (np.round(d.pixels[list(q)].mean(axis=0)).astype(int)
                       for q in ((0, 1, 10, 9), (43, 44, 53, 52)))
        assert image[first[1], first[0]] < 100 < 150 < image[last[1], last[0]]
        _, raw = cv2.findChessboardCorners(image, (9, 6))
        raw = cv2.cornerSubPix(image, raw, (5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS
                               + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)).reshape(-1, 2)
        gap = np.hypot(*(d.pixels[:, None, :] - raw[None, :, :]).transpose(2, 0, 1))
        assert gap.min(axis=1).max() < 0.3


@pytest.mark.slow
def test_the_public_photographs_all_found():
    found, missing, _ = dt.detect(sorted(PUBLIC.glob("*.jpg")), dt.Board(9, 6, 25.0))
    assert len(found) == 12 and not missing and all(d.by_colour for d in found)


@pytest.mark.slow
def test_the_readme_photograph_chain(tmp_path):
    """README, "From calibration photographs to a range size": the commands as printed; the
    board found in all twelve photographs, the pixel error written and the range sized."""
    import re
    import shlex
    import subprocess

    text = (ROOT / "README.md").read_text()
    block = re.search(r"```sh\n(\.venv/bin/montecarlo camera detect.*?)```", text, re.S)
    commands = re.sub(r"\\\n\s*", " ", block.group(1)).strip().splitlines()
    assert [shlex.split(c)[1] for c in commands] == ["camera", "diagnose", "size"]
    (tmp_path / "tests").symlink_to(ROOT / "tests")
    outputs = []
    for command in commands:
        args = [str(p) for a in shlex.split(command)[1:]
                for p in (sorted(tmp_path.glob(a)) if "*" in a or "[" in a else [a])]
        done = subprocess.run([sys.executable, "-m", "montecarlo", *args], cwd=tmp_path,
                              capture_output=True, text=True, timeout=3600)
        assert done.returncode == 0, done.stderr[-2000:]
        outputs.append(done.stdout)
    assert "found in 12 of 12 images (640x480 px), 648 corners" in outputs[0]
    assert "pixel_px" in (tmp_path / "camera_errors.toml").read_text()
    assert (tmp_path / "results" / "camera" / "image_residuals_1.png").is_file()
