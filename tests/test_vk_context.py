"""Device choice and the errors a user sees when Vulkan cannot be had."""
import subprocess
import sys

import pytest

from gs_ibl_addon.core.vk import VulkanContext, VulkanUnavailable, get_context


def test_default_device_is_usable():
    ctx = get_context()
    assert ctx.device_name and ctx.timestamp_period_ns > 0


def test_unknown_device_request_names_the_devices_there():
    with pytest.raises(VulkanUnavailable) as e:
        VulkanContext("no-such-gpu-xyz")
    msg = str(e.value)
    assert "GS_IBL_DEVICE='no-such-gpu-xyz'" in msg and get_context().device_name in msg


def test_cpu_request_picks_lavapipe_when_present():
    try:
        ctx = VulkanContext("cpu")
    except VulkanUnavailable:
        pytest.skip("no CPU Vulkan device here (a GPU-only machine)")
    assert ctx.is_cpu
    ctx.close()


def test_no_vulkan_loader_gives_the_install_hint(tmp_path):
    # A process whose loader finds no driver at all: the message must say what to install, not show a traceback.
    code = ("from gs_ibl_addon.cli import main; import sys; "
            "sys.exit(main(['render', 'samples/room.ply', '--camera', '0', '0', '1', '--look-at', '1', '0', '1', "
            f"'--size', '8', '8', '--out', r'{tmp_path / 'x.exr'}']))")
    env = {"VK_ICD_FILENAMES": str(tmp_path / "none.json"), "VK_DRIVER_FILES": str(tmp_path / "none.json"),
           "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       cwd=__file__.rsplit("/tests/", 1)[0])
    assert r.returncode == 2, r.stderr
    assert "apt-get install libvulkan1 mesa-vulkan-drivers" in r.stderr and "Traceback" not in r.stderr


def test_install_hint_names_what_to_install_per_platform():
    from gs_ibl_addon.core.vk.context import _install_hint
    assert "MoltenVK" in _install_hint("darwin")
    assert "vulkan-1.dll" in _install_hint("win32")
    assert "mesa-vulkan-drivers" in _install_hint("linux")
