"""Every ```python block of README.md and docs/*.md runs as written (and marked bash blocks).

How the blocks run:

- Page by page, each page in a fresh interpreter, its blocks top to bottom in
  one namespace: a block may use what an earlier block of the same page
  defined, as a reader going down the page would.
- The working directory is a fresh temporary folder with links to the
  repository's committed ``results/`` and ``examples/``, so paths written as
  from the repository root resolve, and whatever a block writes (``runs/``,
  ``outputs/``) lands in the temporary folder.
- A block is compiled under its page's path with its own line numbers, so a
  traceback points at the page and the line in it (``docs/agents.md, line 61``).
- Each block is one test, ``test_block[docs/agents.md:58]`` (the line of its
  opening fence); a block after a failed one of the same page is not run and
  says which one failed.

Markers, as HTML comments (invisible on the rendered page) on the lines just
before a block's opening fence, one or more, e.g.::

    <!-- docs-test: needs torchrl -->
    <!-- docs-test: slow -->

- ``needs EXTRA``: the block needs an optional extra (``torchrl``, ``ray``,
  ``rllib``, ``benchmarl``, ``onnx``); it is skipped, naming the extra, unless
  the extra's modules import. Later blocks that use its names need the marker too.
- ``slow``: the block takes long (a real training budget); it runs only under
  ``pytest -m slow``. Give the reader a short variant in a block next to it,
  which runs by default.
- ``run``: a ```bash block that runs too (``bash -euo pipefail``, in the same
  working directory, with this interpreter's console scripts on ``PATH``), as
  the README's tour does; other bash blocks are not run (their commands are
  covered by the commands' own tests, and their budgets are real ones).

Markers above a block that does not run are an error, as is an unknown
marker. Relative links of the pages must point at files that exist.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import ROOT

#: Extra -> the modules it brings (all must import for its blocks to run).
EXTRAS = {
    "torchrl": ("torchrl", "tensordict"),
    "ray": ("ray",),
    "rllib": ("ray.rllib",),
    "benchmarl": ("benchmarl",),
    "onnx": ("onnx", "onnxruntime"),
}

#: Extra -> how to install it (pyproject.toml's extras; BenchMARL itself without its pins).
INSTALL = {
    "torchrl": 'pip install -e ".[torchrl]"',
    "ray": 'pip install -e ".[rl,ray]"',
    "rllib": 'pip install -e ".[rl,rllib]"',
    "benchmarl": 'pip install -e ".[benchmarl]" && pip install --no-deps benchmarl==1.5.2',
    "onnx": 'pip install -e ".[onnx]"',
}

#: Committed folders a block may read by their repository-relative path.
LINKED = ("results", "examples")

#: Seconds a page may take before its interpreter is stopped.
PAGE_TIMEOUT = 900

_FENCE = re.compile(r"^```(\w*)\s*$")
_MARKER = re.compile(r"^<!--\s*docs-test:\s*(.*?)\s*-->\s*$")


@dataclasses.dataclass(frozen=True)
class Block:
    """One block to run: where it is, its language, its code and its markers."""

    page: str  # path relative to the repository root
    line: int  # line of the opening fence, from 1
    language: str  # "python", or "bash" for a block marked ``run``
    code: str
    slow: bool
    needs: tuple[str, ...]

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}"


def _markers(page: str, lines: list[str], start: int) -> tuple[bool, bool, list[str]]:
    """(run, slow, needs) from the marker comments just above line index ``start``."""
    run, slow, needs = False, False, []
    above = start - 1
    while above >= 0 and (marker := _MARKER.match(lines[above])):
        for word in marker.group(1).split(";"):
            key, _, value = word.strip().partition(" ")
            if key in ("slow", "run") and not value:
                run, slow = run or key == "run", slow or key == "slow"
            elif key == "needs" and value.strip() in EXTRAS:
                needs.append(value.strip())
            else:
                raise ValueError(
                    f"{page}:{above + 1}: unknown docs-test marker {word.strip()!r}; use "
                    f"'slow', 'run' or 'needs EXTRA' with EXTRA one of {sorted(EXTRAS)}"
                )
        above -= 1
    return run, slow, needs


def parse_blocks(page: str, text: str) -> list[Block]:
    """The page's ```python blocks, and its ```bash blocks marked ``run``, with their markers.

    Raises:
        ValueError: An unclosed fence, a marker this module does not understand (a
            typo would otherwise silently run or skip a block), or markers above a
            block that is not run.
    """
    blocks: list[Block] = []
    lines = text.splitlines()
    index = 0
    while index < len(lines):
        fence = _FENCE.match(lines[index])
        if not fence:
            index += 1
            continue
        start = index
        end = next((k for k in range(start + 1, len(lines)) if lines[k].startswith("```")), None)
        if end is None:
            raise ValueError(f"{page}:{start + 1}: code block never closed")
        language = fence.group(1)
        run, slow, needs = _markers(page, lines, start)
        runs = language == "python" or (language == "bash" and run)
        if (run and language != "bash") or (not runs and (slow or needs)):
            raise ValueError(
                f"{page}:{start + 1}: docs-test markers on a ```{language} block; 'run' is "
                "for ```bash blocks, 'slow' and 'needs' for blocks that run"
            )
        if runs:
            code = "\n".join(lines[start + 1 : end]) + "\n"
            blocks.append(Block(page, start + 1, language, code, slow, tuple(needs)))
        index = end + 1
    return blocks


def _pages() -> list[str]:
    return ["README.md", *(f"docs/{p.name}" for p in sorted((ROOT / "docs").glob("*.md")))]


def _all_blocks() -> list[Block]:
    return [b for page in _pages() for b in parse_blocks(page, (ROOT / page).read_text())]


def _missing_extras(block: Block) -> list[str]:
    def installed(module: str) -> bool:
        try:
            return importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:  # a parent package is missing
            return False

    return [e for e in block.needs if not all(installed(m) for m in EXTRAS[e])]


#: Runs in the page's interpreter: argv[1] is a JSON list of [page, line, language, code]
#: to run in order; prints one JSON line per block, "ok" or the error, and stops at the
#: first error. Python blocks share one namespace; bash blocks run in ``bash -e``.
_RUNNER = textwrap.dedent(
    """
    import json, subprocess, sys, traceback
    namespace = {"__name__": "__main__"}
    for page, line, language, code in json.loads(sys.argv[1]):
        if language == "bash":
            done = subprocess.run(
                ["bash", "-euo", "pipefail", "-c", code], capture_output=True, text=True
            )
            outcome = "ok" if done.returncode == 0 else (
                f"bash exited {done.returncode}:\\n{done.stdout[-2000:]}{done.stderr[-3000:]}"
            )
        else:
            source = "\\n" * line + code  # the code's first line is the page's line + 1
            try:
                exec(compile(source, page, "exec"), namespace)
                outcome = "ok"
            except BaseException:
                outcome = traceback.format_exc()
        print(json.dumps([line, outcome]), flush=True)
        if outcome != "ok":
            break
    """
)


def _run_page(page: str, blocks: list[Block], workdir: Path) -> dict[int, str]:
    """Run ``blocks`` of ``page`` in order in one fresh interpreter; fence line -> outcome."""
    for name in LINKED:
        (workdir / name).symlink_to(ROOT / name, target_is_directory=True)
    payload = json.dumps([[b.page, b.line, b.language, b.code] for b in blocks])
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    env.setdefault("NUMBA_NUM_THREADS", "1")
    # the console scripts of this interpreter (cpf-train, cpf-bench) for bash blocks
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["MPLBACKEND"] = "Agg"
    try:
        result = subprocess.run(
            [sys.executable, "-c", _RUNNER, payload],
            cwd=workdir,
            env=env,
            capture_output=True,
            text=True,
            timeout=PAGE_TIMEOUT,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return {blocks[0].line: f"{page}: the page's blocks took over {PAGE_TIMEOUT} s"}
    outcomes: dict[int, str] = {}
    for row in result.stdout.splitlines():
        if row.startswith("[") and row.endswith("]"):
            try:
                line, outcome = json.loads(row)
            except ValueError:  # a block printed something that looks like a list
                continue
            outcomes[int(line)] = outcome
    if result.returncode != 0 and not any(o != "ok" for o in outcomes.values()):
        first_missing = next((b.line for b in blocks if b.line not in outcomes), blocks[-1].line)
        outcomes[first_missing] = (
            f"interpreter exited {result.returncode}:\n{result.stderr[-3000:]}"
        )
    return outcomes


_BLOCKS = _all_blocks()
_CACHE: dict[tuple[str, bool], dict[int, str]] = {}


def _page_outcomes(block: Block, with_slow: bool, tmp_factory: pytest.TempPathFactory) -> dict:
    """The page's outcomes, run once per session (with its slow blocks for a slow block)."""
    key = (block.page, with_slow)
    if key not in _CACHE:
        runnable = [
            b
            for b in _BLOCKS
            if b.page == block.page and (with_slow or not b.slow) and not _missing_extras(b)
        ]
        workdir = tmp_factory.mktemp(re.sub(r"\W", "_", block.page))
        _CACHE[key] = _run_page(block.page, runnable, workdir)
    return _CACHE[key]


def _params() -> list:
    return [pytest.param(b, id=b.id, marks=[pytest.mark.slow] if b.slow else []) for b in _BLOCKS]


@pytest.mark.parametrize("block", _params())
def test_block(block: Block, request: pytest.FixtureRequest) -> None:
    """The block runs after the blocks above it on its page."""
    missing = _missing_extras(block)
    if missing:
        hints = "; ".join(f"{extra}: {INSTALL[extra]}" for extra in missing)
        pytest.skip(f"{block.id} needs the {', '.join(missing)} extra ({hints})")
    outcomes = _page_outcomes(block, block.slow, request.getfixturevalue("tmp_path_factory"))
    outcome = outcomes.get(block.line)
    if outcome is None:
        failed = [line for line, o in outcomes.items() if o != "ok"]
        where = f"{block.page}:{failed[0]}" if failed else "an earlier block"
        pytest.fail(f"{block.id} not run: the block at {where} failed first")
    what = f"the ```{block.language} block starting here failed"
    assert outcome == "ok", f"{block.id}: {what}:\n{outcome}"


def test_pages_have_blocks_and_markers_parse() -> None:
    """The collection itself: the README has blocks, every marker is understood."""
    assert any(b.page == "README.md" for b in _BLOCKS)
    assert len(_BLOCKS) >= 10


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("```python\nx = 1\n```\n", [(1, "python", False, ())]),
        ("<!-- docs-test: slow -->\n```python\nx = 1\n```\n", [(2, "python", True, ())]),
        (
            "<!-- docs-test: needs torchrl -->\n<!-- docs-test: slow -->\n```python\n```\n",
            [(3, "python", True, ("torchrl",))],
        ),
        ("```bash\nls\n```\n\n```python\ny = 2\n```\n", [(5, "python", False, ())]),
        ("<!-- docs-test: run; slow -->\n```bash\nls\n```\n", [(2, "bash", True, ())]),
    ],
    ids=["plain", "slow", "two-markers", "bash-not-run", "bash-run"],
)
def test_parse_blocks(text: str, expected: list) -> None:
    got = [(b.line, b.language, b.slow, b.needs) for b in parse_blocks("page.md", text)]
    assert got == expected


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("<!-- docs-test: sloow -->\n```python\n```\n", "unknown docs-test marker 'sloow'"),
        ("<!-- docs-test: needs gpu -->\n```python\n```\n", "unknown docs-test marker"),
        ("<!-- docs-test: run -->\n```python\n```\n", "markers on a ```python block"),
        ("<!-- docs-test: slow -->\n```bash\nls\n```\n", "markers on a ```bash block"),
        ("```python\nx = 1\n", "never closed"),
    ],
    ids=["typo", "unknown-extra", "run-on-python", "slow-on-bash-not-run", "unclosed"],
)
def test_parse_blocks_refuses(text: str, error: str) -> None:
    with pytest.raises(ValueError, match=error):
        parse_blocks("page.md", text)


def test_a_failing_block_is_reported_at_its_page_line(tmp_path: Path) -> None:
    """A traceback names the page and the line of the failing statement in it."""
    text = "intro\n\n```python\nx = 1\n```\n\n```python\ny = x + 1\nundefined_name\n```\n"
    blocks = parse_blocks("docs/example.md", text)
    outcomes = _run_page("docs/example.md", blocks, tmp_path)
    assert outcomes[3] == "ok"
    assert 'File "docs/example.md", line 9' in outcomes[7]
    assert "NameError" in outcomes[7]


def test_a_failing_bash_block_stops_the_page(tmp_path: Path) -> None:
    text = (
        "<!-- docs-test: run -->\n```bash\necho hello > note.txt\nfalse\n```\n\n"
        "```python\nx = 1\n```\n"
    )
    blocks = parse_blocks("docs/example.md", text)
    outcomes = _run_page("docs/example.md", blocks, tmp_path)
    assert outcomes[2].startswith("bash exited 1")
    assert 7 not in outcomes  # not run after the failure
    assert (tmp_path / "note.txt").read_text() == "hello\n"


_LINK = re.compile(r"\]\(([^)\s]+)\)")


def _anchors(markdown: Path) -> set[str]:
    """GitHub's anchors of a page's headings: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"```.*?```", "", markdown.read_text(), flags=re.DOTALL)
    headings = re.findall(r"^#+ +(.+?) *$", text, flags=re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", h.lower()).replace(" ", "-") for h in headings}


@pytest.mark.parametrize("page", [*_pages(), "CONTRIBUTING.md"])
def test_relative_links_resolve(page: str) -> None:
    """Every relative link (and image) of the page points at a file that exists, and a
    link to a heading (``page.md#anchor``, ``#anchor``) at a heading that exists."""
    text = re.sub(r"```.*?```", "", (ROOT / page).read_text(), flags=re.DOTALL)
    broken = []
    for target in _LINK.findall(text):
        path, _, anchor = target.partition("#")
        if re.match(r"[a-z]+:", path):
            continue  # a URL
        file = (ROOT / page).parent / path if path else ROOT / page
        if not file.exists():
            broken.append(target)
        elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
            broken.append(target)
    assert not broken, f"{page}: links to missing files or headings: {broken}"


#: The README's two set-up commands, verbatim: new users paste them, and CI runs the second.
SETUP_COMMANDS = (
    "python3 -m venv .venv && . .venv/bin/activate && pip install -e . && cpf-run",
    "python3 -m venv .venv && . .venv/bin/activate && pip install torch==2.13.0 && "
    'pip install -e ".[rl,dev]" && python -m pytest',
)


def test_readme_keeps_the_setup_commands() -> None:
    lines = (ROOT / "README.md").read_text().splitlines()
    for command in SETUP_COMMANDS:
        assert command in lines, f"README.md: the set-up line {command!r} changed"


def test_anchors_follow_github(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("# Title\n\n## 10. The paper's scenario (n = 5)\n\n```bash\n# code\n```\n")
    assert _anchors(page) == {"title", "10-the-papers-scenario-n--5"}
