"""The fuzz corpus (tests/fuzz_corpus.py) through the real command line, one process per input: every bad file and
every bad option is refused with exactly one line on stderr naming the file or option, exit code 2, no traceback,
no hang (a subprocess timeout), and nothing written: no output, no temporary file left behind.

The same damaged files through Blender's importer are in tests/test_blender_formats.py's corpus test.
"""
from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import pytest

from fuzz_corpus import command_cases, file_cases

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TIMEOUT_S = 120  # a refusal takes about a second; a hang or a render would take far longer


def _run(argv: list[str]) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "gs_ibl_addon", *argv], capture_output=True, text=True,
                          timeout=TIMEOUT_S, env=env, cwd=ROOT)


def _snapshot(folder: str) -> set[str]:
    return {os.path.relpath(os.path.join(r, n), folder) for r, ds, fs in os.walk(folder) for n in ds + fs}


def _assert_one_line(name: str, res: subprocess.CompletedProcess, *words: str) -> str:
    err = res.stderr.strip()
    assert res.returncode == 2, (name, res.returncode, err, res.stdout)
    assert "Traceback" not in err, (name, err)
    assert len(err.splitlines()) == 1 and err.startswith("error: "), (name, err)
    for w in words:
        assert w in err, (name, w, err)
    return err


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    folder = str(tmp_path_factory.mktemp("fuzz"))
    return folder, file_cases(os.path.join(folder, "files")), command_cases(os.path.join(folder, "cmd"))


def test_corpus_is_large_enough(corpus):
    _, files, commands = corpus
    assert len(files) >= 30 and len(commands) >= 30, (len(files), len(commands))


def test_every_bad_file_is_refused_with_one_line(corpus):
    folder, files, _ = corpus
    before = _snapshot(folder)
    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(lambda case: _run(["info", case[1]]), files))
    for (name, path), res in zip(files, results):
        # the message names the file (its own path, or for the SOG folder the folder)
        _assert_one_line(name, res, os.path.basename(path))
    assert _snapshot(folder) == before  # reading writes nothing


def test_every_bad_option_is_refused_before_any_work(corpus):
    folder, _, commands = corpus
    cmd_folder = os.path.join(folder, "cmd")
    before = _snapshot(cmd_folder)
    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(lambda case: _run(case[1]), commands))
    for (name, argv), res in zip(commands, results):
        err = _assert_one_line(name, res)
        option = name.split()[1] if name.split()[1].startswith("--") else None
        if option:
            assert option in err, (name, err)
        assert "read " not in res.stderr and "%]" not in res.stderr, (name, res.stderr)  # nothing was read or rendered
    after = _snapshot(cmd_folder)
    assert after == before, sorted(after ^ before)  # no output, no partial file, no write test left behind
