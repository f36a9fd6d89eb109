"""Everything about running dndenoise that does not need Blender: finding and
checking the program, naming a sequence's frames, the command line, and a job
that reads its progress without blocking. Free of bpy, so that the tests
drive it as the modal operator does without a Blender window."""

import os
import queue
import re
import shutil
import subprocess
import threading

# --temporal, --frames and the Denoised layer, which this add-on relies on, came with 0.1.0.
MIN_VERSION = (0, 1, 0)
QUALITIES = ("fast", "balanced", "high")
DEVICES = ("cpu", "cuda")


class DenoiseError(Exception):
    """One line for the user; nothing has been written."""


def find_dndenoise(preferred=""):
    """The dndenoise to run: the add-on preference if set, else the one on PATH."""
    if preferred:
        path = os.path.abspath(os.path.expanduser(preferred))
        if not (os.path.isfile(path) and os.access(path, os.X_OK)):
            raise DenoiseError(f"dndenoise not found at {path} (add-on preferences)")
        return path
    path = shutil.which("dndenoise")
    if not path:
        raise DenoiseError("dndenoise not found on PATH; set its path in the add-on preferences")
    return path


def check_version(exe):
    """Returns dndenoise's version, or says in one line why it cannot be used."""
    try:
        out = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=60)
    except OSError as e:
        raise DenoiseError(f"{exe}: cannot run ({e.strerror})") from None
    except subprocess.TimeoutExpired:
        raise DenoiseError(f"{exe} --version did not answer within 60 s") from None
    match = re.match(r"dndenoise (\d+)\.(\d+)\.(\d+)", out.stdout)
    if out.returncode != 0 or not match:
        raise DenoiseError(f"{exe} is not dndenoise ('{exe} --version' printed no dndenoise version)")
    version = tuple(int(v) for v in match.groups())
    if version < MIN_VERSION:
        raise DenoiseError(f"{exe} is dndenoise {'.'.join(map(str, version))}; this add-on needs "
                           f"{'.'.join(map(str, MIN_VERSION))} or newer")
    return version


class Sequence:
    """Numbered frames: prefix + the frame number in `width` digits + suffix."""

    def __init__(self, prefix, width, suffix, frames):
        self.prefix, self.width, self.suffix, self.frames = prefix, width, suffix, frames

    def path(self, frame):
        return f"{self.prefix}{frame:0{self.width}d}{self.suffix}"

    def printf(self):
        """The pattern as dndenoise (OpenImageIO) reads it."""
        return f"{self.prefix.replace('%', '%%')}%0{self.width}d{self.suffix.replace('%', '%%')}"

    def blender_pattern(self):
        return f"{self.prefix}{'#' * self.width}{self.suffix}"

    def frame_range(self):
        """--frames for these frames: first-last, with a step where they have one."""
        first, last = self.frames[0], self.frames[-1]
        step = self.frames[1] - first if len(self.frames) > 1 else 1
        return f"{first}-{last}" + (f"x{step}" if step > 1 else "")


_NUMBERED = re.compile(r"^(.*?)(\d+)(\.exr)$", re.IGNORECASE)


def _scan(folder, prefix, width, suffix):
    frames = []
    for name in os.listdir(folder):
        m = _NUMBERED.match(name)
        if m and (m.group(1), len(m.group(2)), m.group(3)) == (prefix, width, suffix):
            frames.append(int(m.group(2)))
    return sorted(frames)


def sequence_of(path):
    """The EXR sequence a chosen frame or folder holds; one line if it holds none or several."""
    path = os.path.abspath(path)
    if os.path.isdir(path):
        groups = {}
        for name in sorted(os.listdir(path)):
            m = _NUMBERED.match(name)
            if m:
                groups.setdefault((m.group(1), len(m.group(2)), m.group(3)), 0)
        if not groups:
            raise DenoiseError(f"{path}: not a frame sequence (no numbered EXR files such as name.0001.exr)")
        if len(groups) > 1:
            names = ", ".join(p + "#" * w + s for p, w, s in groups)
            raise DenoiseError(f"{path}: holds {len(groups)} sequences ({names}); choose a frame of one")
        (prefix, width, suffix), = groups
        return Sequence(os.path.join(path, prefix), width, suffix, _scan(path, prefix, width, suffix))
    if not os.path.isfile(path):
        raise DenoiseError(f"{path}: no such file or folder")
    folder, name = os.path.split(path)
    m = _NUMBERED.match(name)
    if not m:
        raise DenoiseError(f"{path}: not a frame of a sequence (an EXR named like name.0001.exr)")
    prefix, digits, suffix = m.groups()
    return Sequence(os.path.join(folder, prefix), len(digits), suffix,
                    _scan(folder, prefix, len(digits), suffix))


def sequence_from_paths(path_a, frame_a, path_b, frames):
    """The sequence whose frame `frame_a` is path_a and another frame path_b (as
    Blender's frame_path names them): the frame number is where they differ."""
    start = 0
    while start < min(len(path_a), len(path_b)) and path_a[start] == path_b[start]:
        start += 1
    end = 0
    while end < min(len(path_a), len(path_b)) - start and path_a[-1 - end] == path_b[-1 - end]:
        end += 1
    while start > 0 and path_a[start - 1].isdigit():
        start -= 1
    stop = len(path_a) - end
    while stop < len(path_a) and path_a[stop].isdigit():
        stop += 1
    digits = path_a[start:stop]
    if not digits.isdigit() or int(digits) != frame_a:
        raise DenoiseError(f"{path_a}: the output path does not name frames by number")
    return Sequence(path_a[:start], len(digits), path_a[stop:], frames)


def output_sequence(pattern, frames):
    """An output pattern in Blender's way (a run of # per digit, // for the .blend's folder
    resolved by the caller); without #, four digits are added before the extension."""
    folder, name = os.path.split(pattern)
    if "#" not in name:
        stem, ext = os.path.splitext(name)
        name = stem + "####" + (ext or ".exr")
    run = list(re.finditer(r"#+", name))[-1]
    return Sequence(os.path.join(folder, name[:run.start()]), run.end() - run.start(),
                    name[run.end():], frames)


def command(exe, source, output, quality="balanced", temporal=True, passes=False, device="cpu",
            threads=0, view_layer="", window=0):
    """dndenoise's command line for the frames of `source` into `output` (Sequences)."""
    if quality not in QUALITIES:
        raise DenoiseError(f"quality must be one of {', '.join(QUALITIES)}, got '{quality}'")
    if device not in DEVICES:
        raise DenoiseError(f"device must be one of {', '.join(DEVICES)}, got '{device}'")
    cmd = [exe, source.printf(), "-o", output.printf(), "--frames", source.frame_range(),
           "-q", quality, "--temporal", "on" if temporal else "off", "--device", device, "-v"]
    if passes:
        cmd.append("--passes")
    if threads:
        cmd += ["--threads", str(threads)]
    if view_layer:
        cmd += ["--view-layer", view_layer]
    if window:
        cmd += ["--window", str(window)]
    return cmd


# -v's progress line off a terminal: "dndenoise: shot.0002.exr [2/3]  40%  elapsed 3s  ETA 9s".
_PROGRESS = re.compile(r"\[(\d+)/(\d+)\]\s+(\d+)%")


class Job:
    """dndenoise in a child process; a thread collects its lines so that Blender's UI
    can poll them from a timer without blocking."""

    def __init__(self, cmd, frames):
        self.cmd = cmd
        self.frames = frames  # how many frames the command writes
        self.written = 0
        self.fraction = 0.0
        self.warnings = []   # lines worth a warning in Blender (frame by frame, clamped values)
        self.lines = []      # everything dndenoise printed
        self.cancelled = False
        self._lines = queue.Queue()
        try:
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL, text=True, bufsize=1)
        except OSError as e:
            raise DenoiseError(f"{cmd[0]}: cannot run ({e.strerror})") from None
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self._lines.put(line.rstrip("\n"))
        self._lines.put(None)

    def poll(self):
        """Takes the lines printed since the last call; True once dndenoise has ended."""
        while True:
            try:
                line = self._lines.get_nowait()
            except queue.Empty:
                return False
            if line is None:
                self.proc.wait()
                return True
            self._take(line)

    def _take(self, line):
        self.lines.append(line)
        m = _PROGRESS.search(line)
        if m:
            done, total, percent = (int(g) for g in m.groups())
            self._advance((done - 1 + percent / 100) / total)
        elif line.startswith("dndenoise: wrote "):
            # The temporal filter denoises frames ahead as neighbours and then has no
            # progress to report for them: the frames written count as well.
            self.written += 1
            self._advance(self.written / self.frames)
        elif "frame by frame" in line or "clamped" in line:
            self.warnings.append(line)

    def _advance(self, fraction):
        self.fraction = max(self.fraction, min(1.0, fraction))  # never backwards

    def wait(self, on_progress=None):
        """Blocks until dndenoise ends (headless use); calls on_progress(fraction) as it goes."""
        last = -1.0
        while True:
            line = self._lines.get()
            if line is None:
                self.proc.wait()
                return
            self._take(line)
            if on_progress and self.fraction != last:
                last = self.fraction
                on_progress(self.fraction)

    def cancel(self):
        """SIGTERM: dndenoise removes its unfinished file and exits 143."""
        self.cancelled = True
        if self.proc.poll() is None:
            self.proc.terminate()

    def error(self):
        """None on success, else the one line to show."""
        code = self.proc.returncode
        if code == 0:
            return None
        if self.cancelled:
            return "dndenoise cancelled; the frames finished before stay written"
        last = next((l for l in reversed(self.lines) if l.strip()), "")
        return last or f"dndenoise exited with code {code}"
