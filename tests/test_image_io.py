"""EXR/PNG I/O through OpenImageIO: real files in a temp folder, read back and compared."""
import numpy as np
import pytest

from gs_ibl_addon.core.image_io import ImageIOError, read_exr, write_exr, write_png_preview


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_float_round_trip_is_exact(tmp_path, channels):
    rng = np.random.default_rng(1)
    a = (rng.random((9, 13, channels)) * 1e4 - 10).astype(np.float32)  # HDR values and negatives survive float
    write_exr(tmp_path / "a.exr", a)
    b = read_exr(tmp_path / "a.exr")
    assert b.dtype == np.float32 and b.shape == a.shape
    np.testing.assert_array_equal(b, a)


def test_half_round_trip_within_half_precision(tmp_path):
    import OpenImageIO as oiio
    rng = np.random.default_rng(2)
    a = (rng.random((8, 16, 3)) * 100).astype(np.float32)
    write_exr(tmp_path / "h.exr", a, half=True)
    inp = oiio.ImageInput.open(str(tmp_path / "h.exr"))
    spec = inp.spec()
    inp.close()
    assert spec.format == oiio.TypeDesc(oiio.HALF) and tuple(spec.channelnames) == ("R", "G", "B")
    b = read_exr(tmp_path / "h.exr")
    # half has an 11-bit significand: relative rounding error <= 2^-11 = 4.9e-4
    assert np.max(np.abs(b - a) / np.maximum(a, 1e-3)) <= 2.0 ** -11


def test_rgba_channel_names(tmp_path):
    import OpenImageIO as oiio
    write_exr(tmp_path / "a.exr", np.ones((2, 3, 4), np.float32))
    inp = oiio.ImageInput.open(str(tmp_path / "a.exr"))
    assert tuple(inp.spec().channelnames) == ("R", "G", "B", "A")
    inp.close()


def test_png_preview_is_srgb_8bit(tmp_path):
    img = np.zeros((2, 3, 3), np.float32)
    img[0, 0] = 0.5  # linear 0.5 -> sRGB 0.7354 -> 188
    img[0, 1] = 7.0  # clipped to white
    write_png_preview(tmp_path / "p.png", img, exposure=0.0)
    b = read_exr(tmp_path / "p.png")  # OIIO returns [0, 1] floats for 8-bit
    assert round(float(b[0, 0, 0]) * 255) == 188
    assert b[0, 1, 0] == 1.0 and b[1, 2, 0] == 0.0
    write_png_preview(tmp_path / "q.png", img, exposure=1.0)  # 0.5 * 2 = 1.0 -> white
    assert read_exr(tmp_path / "q.png")[0, 0, 0] == 1.0


def test_clear_errors(tmp_path):
    with pytest.raises(ImageIOError, match="no such file"):
        read_exr(tmp_path / "missing.exr")
    with pytest.raises(ImageIOError, match="does not exist"):
        write_exr(tmp_path / "nope" / "a.exr", np.zeros((2, 2, 3)))
    with pytest.raises(ImageIOError, match="H x W x C"):
        write_exr(tmp_path / "a.exr", np.zeros((2, 2, 5)))
    with pytest.raises(ImageIOError, match="non-finite"):
        write_exr(tmp_path / "a.exr", np.full((2, 2, 3), np.nan))
    (tmp_path / "junk.exr").write_bytes(b"not an image")
    with pytest.raises(ImageIOError, match="junk.exr"):
        read_exr(tmp_path / "junk.exr")
