"""Hostile rig files (session 42, helper hostile42): pslog TOML, anipose, Pose2Sim and OpenCV
files broken in every way a clumsy user or a bad tool could, through ``rig check``, ``rig
show``, ``rig import``, ``rig export`` and then (for those accepted) ``fuse --rig``,
``simulate --rig`` and ``sync``.

Run: python benchmarks/session42/hostile/rigs.py WORKDIR (WORKDIR holds s.mcap, f.mcap, rig.toml,
a.toml, p.toml, o.yml, o.xml, o.json as made by README's commands; prints one line a case)."""

from __future__ import annotations

import hashlib
import os
import sys
from collections import Counter
from pathlib import Path

from _run import run

work = Path(sys.argv[1])
cases_dir = work / "rigcases"
cases_dir.mkdir(exist_ok=True)
base = (work / "rig.toml").read_text()
ani = (work / "a.toml").read_text()
p2s = (work / "p.toml").read_text()
ocv = (work / "o.yml").read_text()
ocx = (work / "o.xml").read_text()
ocj = (work / "o.json").read_text()


def cam(i=1, **over):
    d = {"name": f'"cam{i}"', "width": "640", "height": "480",
         "K": "[[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]",
         "dist": "[0.0, 0.0, 0.0, 0.0, 0.0]",
         "R": "[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]",
         "t": f"[{-0.5 * i}, 0.0, 3.0]", "fps": "30.0", "offset": "0.0"}
    d.update(over)
    return "[[camera]]\n" + "".join(f"{k} = {v}\n" for k, v in d.items() if v is not None)


def rig(*cams):
    return "\n".join(cams)


two = (cam(2), cam(3))
texts: dict[str, str | bytes] = {
    "ok": rig(cam(1), *two),
    "empty": "",
    "only name": 'name = "x"\n',
    "camera = []": "camera = []\n",
    "truncated": base[: len(base) // 2],
    "truncated mid K": base[: base.index("K = ") + 20],
    "K nan": rig(cam(1, K="[[nan, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]"), *two),
    "K inf": rig(cam(1, K="[[inf, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]"), *two),
    "K singular": rig(cam(1, K="[[400.0, 400.0, 319.5], [0.0, 0.0, 239.5], [0.0, 0.0, 1.0]]"),
                      *two),
    "K zero": rig(cam(1, K="[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]"), *two),
    "K negative f": rig(cam(1, K="[[-400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]"),
                        *two),
    "K huge skew": rig(cam(1, K="[[400.0, 9e6, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]"),
                       *two),
    "K 1e308": rig(cam(1, K="[[1e308, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]"), *two),
    "K strings": rig(cam(1, K='[["400", 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]'),
                     *two),
    "K ragged": rig(cam(1, K="[[400.0, 0.0], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]"), *two),
    "K flat": rig(cam(1, K="[400.0, 0.0, 319.5, 0.0, 400.0, 239.5, 0.0, 0.0, 1.0]"), *two),
    "K bool": rig(cam(1, K="[[true, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]"), *two),
    "K table": rig(cam(1, K="{a = 1}"), *two),
    "K deep": rig(cam(1, K="[" * 5000 + "]" * 5000), *two),
    "K deeper": rig(cam(1, K="[" * 200000 + "]" * 200000), *two),
    "R not ortho": rig(cam(1, R="[[1.0, 0.1, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]"), *two),
    "R reflection": rig(cam(1, R="[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]"), *two),
    "R zero": rig(cam(1, R="[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]"), *two),
    "R nan": rig(cam(1, R="[[nan, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]"), *two),
    "R 1e-7 off": rig(cam(1, R="[[1.0000001, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]"),
                      *two),
    "R 1e308": rig(cam(1, R="[[1e308, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]"), *two),
    "dist 4": rig(cam(1, dist="[0.0, 0.0, 0.0, 0.0]"), *two),
    "dist 8": rig(cam(1, dist="[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"), *two),
    "dist 0": rig(cam(1, dist="[]"), *two),
    "dist scalar": rig(cam(1, dist="0.0"), *two),
    "dist nan": rig(cam(1, dist="[nan, 0.0, 0.0, 0.0, 0.0]"), *two),
    "dist 1e3": rig(cam(1, dist="[999.0, 0.0, 0.0, 0.0, 0.0]"), *two),
    "dist -0.9 k1": rig(cam(1, dist="[-0.9, 0.5, 0.0, 0.0, 0.3]"), *two),
    "t nan": rig(cam(1, t="[nan, 0.0, 3.0]"), *two),
    "t 1e5": rig(cam(1, t="[1e5, 0.0, 3.0]"), *two),
    "t 2 long": rig(cam(1, t="[0.0, 3.0]"), *two),
    "width 0": rig(cam(1, width="0"), *two),
    "width -1": rig(cam(1, width="-1"), *two),
    "width float": rig(cam(1, width="640.0"), *two),
    "width 1": rig(cam(1, width="1", height="1"), *two),
    "width string": rig(cam(1, width='"640"'), *two),
    "width 2^70": rig(cam(1, width="1180591620717411303424"), *two),
    "fps 0": rig(cam(1, fps="0.0"), *two),
    "fps -30": rig(cam(1, fps="-30.0"), *two),
    "fps nan": rig(cam(1, fps="nan"), *two),
    "fps inf": rig(cam(1, fps="inf"), *two),
    "fps 1e6": rig(cam(1, fps="1e6"), *two),
    "fps 0.1": rig(cam(1, fps="0.1"), *two),
    "fps int": rig(cam(1, fps="30"), *two),
    "fps 2^70": rig(cam(1, fps="1180591620717411303424"), *two),
    "offset -0": rig(cam(1, offset="-0.0"), *two),
    "offset negative": rig(cam(1, offset="-0.001"), *two),
    "offset = period": rig(cam(1, offset="0.03333333333333333"), *two),
    "offset 1e-300": rig(cam(1, offset="1e-300"), *two),
    "offset date": rig(cam(1, offset="1979-05-27"), *two),
    "readout = period": rig(cam(1), cam(2, readout="0.0333333333333"), cam(3)),
    "clock first": rig(cam(1, clock_offset="0.5"), *two),
    "clock 2nd big": rig(cam(1), cam(2, clock_offset="86400.0"), cam(3)),
    "drift 2nd": rig(cam(1), cam(2, clock_drift_ppm="999.0"), cam(3)),
    "drift -0": rig(cam(1, clock_drift_ppm="-0.0"), *two),
    "duplicate names": rig(cam(1), cam(1, t="[-2.0, 0.0, 3.0]"), cam(3)),
    "dup names case": rig(cam(1), cam(1, name='"CAM1"', t="[-2.0, 0.0, 3.0]"), cam(3)),
    "dup names nfc/nfd": rig(cam(1, name='"caf\u00e9"'),
                             cam(2, name='"cafe\u0301"'), cam(3)),
    "newline name": rig(cam(1, name='"cam\\n1"'), *two),
    "unicode name": rig(cam(1, name='"κάμερα 1 📷"'), *two),
    "rtl name": rig(cam(1, name='"\u202ecam1"'), *two),
    "zero-width name": rig(cam(1, name='"cam\u200b1"'), cam(2, name='"cam1"'), cam(3)),
    "empty name": rig(cam(1, name='""'), *two),
    "name int": rig(cam(1, name="1"), *two),
    "name missing": rig(cam(1, name=None), *two),
    "name 64": rig(cam(1, name='"' + "x" * 64 + '"'), *two),
    "name slash": rig(cam(1, name='"a/b"'), *two),
    "name colon": rig(cam(1, name='"a:b"'), *two),
    "name dot": rig(cam(1, name='"."'), *two),
    "name dotdot": rig(cam(1, name='".."'), *two),
    "name backslash": rig(cam(1, name='"a\\\\b"'), *two),
    "name star": rig(cam(1, name='"*"'), *two),
    "name surrogate esc": rig(cam(1, name='"\\uD800"'), *two),
    "name nul": rig(cam(1, name='"a\\u0000b"'), *two),
    "name U+2028": rig(cam(1, name='"a\u2028b"'), *two),
    "name U+FEFF": rig(cam(1, name='"\ufeffcam1"'), *two),
    "same centre": rig(cam(1), cam(2, t="[-0.5, 0.0, 3.0]"), cam(3)),
    "one camera": rig(cam(1)),
    "20 cameras": rig(*(cam(i, t=f"[{-0.2 * i}, 0.0, 3.0]") for i in range(1, 21))),
    "257 cameras": rig(*(cam(i, t=f"[{-0.01 * i}, 0.0, 3.0]") for i in range(1, 258))),
    "camera behind": rig(cam(1, t="[0.0, 0.0, -3.0]"), *two),
    "extra key": rig(cam(1, foo="1"), *two),
    "top extra": "foo = 1\n" + rig(cam(1), *two),
    "camera table not array": "[camera]\nname='cam1'\n",
    "bom": "\ufeff" + rig(cam(1), *two),
    "crlf": rig(cam(1), *two).replace("\n", "\r\n"),
    "binary": bytes(range(256)) * 4,
    "nul bytes": b"\0" * 1000,
    "latin1": ("name = \"caf\xe9\"\n" + rig(cam(1), *two)).encode("latin-1"),
    "utf16": rig(cam(1), *two).encode("utf-16"),
    "huge comment": "#" + "x" * (2 << 20) + "\n" + rig(cam(1), *two),
    "just under 1MB": "#" + "x" * ((1 << 20) - 2000) + "\n" + rig(cam(1), *two),
    "many keys": "\n".join(f"k{i} = {i}" for i in range(50000)),
    "long float": rig(cam(1, fps="30." + "0" * 100000), *two),
    "ani ok": ani,
    "ani no matrix": ani.replace("matrix =", "mtx =", 1),
    "ani size float": ani.replace("size = [640, 480]", "size = [640.5, 480]", 1),
    "ani size 3": ani.replace("size = [640, 480]", "size = [640, 480, 3]", 1),
    "ani size neg": ani.replace("size = [640, 480]", "size = [-640, 480]", 1),
    "ani rot 4": ani.replace("rotation = [2.158798930342465, 0.0, 0.0]",
                             "rotation = [2.158798930342465, 0.0, 0.0, 0.0]"),
    "ani rot nan": ani.replace("rotation = [2.158798930342465, 0.0, 0.0]",
                               "rotation = [nan, 0.0, 0.0]"),
    "ani rot 1e308": ani.replace("rotation = [2.158798930342465, 0.0, 0.0]",
                                 "rotation = [1e308, 0.0, 0.0]"),
    "ani rot 3x3": ani.replace("rotation = [2.158798930342465, 0.0, 0.0]",
                               "rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]"),
    "ani rot 1e20": ani.replace("rotation = [2.158798930342465, 0.0, 0.0]",
                                "rotation = [1e20, 0.0, 0.0]"),
    "ani dist 3": ani.replace("distortions = [0.0, 0.0, 0.0, 0.0, 0.0]",
                              "distortions = [0.0, 0.0, 0.0]", 1),
    "ani dist 14 nz": ani.replace("distortions = [0.0, 0.0, 0.0, 0.0, 0.0]",
                                  "distortions = [" + ", ".join(["0.1"] * 14) + "]", 1),
    "ani no cams": "[metadata]\nname='x'\n",
    "ani cam not table": "cam_0 = 5\n" + ani,
    "ani name int": ani.replace('name = "cam1"', "name = 1", 1),
    "ani no name": ani.replace('name = "cam1"\n', "", 1),
    "ani no names": ani.replace('name = "cam1"\n', "").replace('name = "cam2"\n', "")
    .replace('name = "cam3"\n', ""),
    "ani dup names": ani.replace('name = "cam2"', 'name = "cam1"'),
    "ani fisheye": ani.replace("fps = 30.0", "fisheye = true\nfps = 30.0", 1),
    "ani fps str": ani.replace("fps = 30.0", 'fps = "30"', 1),
    "ani fps nan": ani.replace("fps = 30.0", "fps = nan", 1),
    "ani translation mm-like": ani.replace("translation = [1.0,", "translation = [1000.0,", 1),
    "ani metadata only str": 'metadata = "x"\n' + ani.replace('[metadata]\nname = "paper3"\n',
                                                              ""),
    "p2s ok": p2s,
    "p2s fisheye true": p2s.replace("fisheye = false", "fisheye = true", 1),
    "p2s dist 5 nz": p2s.replace("distortions = [0.0, 0.0, 0.0, 0.0]",
                                 "distortions = [0.1, 0.0, 0.0, 0.0, 0.2]", 1),
    "p2s fisheye str": p2s.replace("fisheye = false", 'fisheye = "no"', 1),
}
ocv_cases = {
    ".yml": {
        "ocv ok": ocv,
        "ocv truncated": ocv[: len(ocv) // 2],
        "ocv rows lie": ocv.replace("rows: 3\n      cols: 3", "rows: 4\n      cols: 3", 1),
        "ocv rows 0": ocv.replace("rows: 3\n      cols: 3", "rows: 0\n      cols: 0", 1),
        "ocv rows huge": ocv.replace("rows: 3\n      cols: 3",
                                     "rows: 100000\n      cols: 100000", 1),
        "ocv dt int": ocv.replace("dt: d", "dt: i", 1),
        "ocv dt u": ocv.replace("dt: d", "dt: u", 1),
        "ocv dt bad": ocv.replace("dt: d", "dt: zz", 1),
        "ocv data nan": ocv.replace("data: [ 400., 0.", "data: [ .nan, 0.", 1),
        "ocv data inf": ocv.replace("data: [ 400., 0.", "data: [ .inf, 0.", 1),
        "ocv data str": ocv.replace("data: [ 400., 0.", "data: [ abc, 0.", 1),
        "ocv no header": ocv.replace("%YAML 1.2\n---\n", ""),
        "ocv yaml 1.0": ocv.replace("%YAML 1.2", "%YAML:1.0"),
        "ocv R and bad rvec": ocv,
        "ocv R nonortho": ocv.replace("data: [ 0., -1., 0., -0.55470019622522915",
                                      "data: [ 0.5, -1., 0., -0.55470019622522915", 1),
        "ocv dist 6": ocv.replace("cols: 5\n      dt: d\n      data: [ 0., 0., 0., 0., 0. ]",
                                  "cols: 6\n      dt: d\n      data: [ 0., 0., 0., 0., 0., 0. ]",
                                  1),
        "ocv dist 14 zeros": ocv.replace(
            "cols: 5\n      dt: d\n      data: [ 0., 0., 0., 0., 0. ]",
            "cols: 14\n      dt: d\n      data: [ " + ", ".join(["0."] * 14) + " ]", 1),
        "ocv width str": ocv.replace("image_width: 640", "image_width: abc", 1),
        "ocv width float": ocv.replace("image_width: 640", "image_width: 640.5", 1),
        "ocv width huge": ocv.replace("image_width: 640", "image_width: 99999999999999999999",
                                      1),
        "ocv name int": ocv.replace("camera_name: cam1", "camera_name: 5", 1),
        "ocv name newline": ocv.replace("camera_name: cam1", 'camera_name: "a\\nb"', 1),
        "ocv dup name": ocv.replace("camera_name: cam2", "camera_name: cam1", 1),
        "ocv alias": ocv.replace("camera_0:", "camera_0: &a", 1) + "camera_9: *a\n",
        "ocv anchors bomb": "%YAML 1.2\n---\n" + "a: &a [" + ",".join(["1"] * 10) + "]\n"
        + "".join(f"{c}: &{c} [" + ",".join([f"*{p}"] * 10) + "]\n"
                  for p, c in zip("abcdefgh", "bcdefghi", strict=True)),
        "ocv tabs": ocv.replace("   ", "\t"),
        "ocv empty": "",
        "ocv header only": "%YAML 1.2\n---\n",
        "ocv scalar top": "%YAML 1.2\n---\n5\n",
        "ocv list top": "%YAML 1.2\n---\n- 1\n- 2\n",
        "ocv binary": bytes(range(256)),
        "ocv deep": "%YAML 1.2\n---\na: " + "[" * 5000 + "]" * 5000 + "\n",
    },
    ".xml": {
        "xml ok": ocx,
        "xml truncated": ocx[: len(ocx) // 2],
        "xml entity bomb": '<?xml version="1.0"?>\n<!DOCTYPE l [<!ENTITY a "aaaaaaaaaa">'
        + "".join(f'<!ENTITY {c} "' + f"&{p};" * 10 + '">' for p, c in zip("abcdefgh",
                                                                          "bcdefghi",
                                                                          strict=True))
        + "]>\n<opencv_storage><x>&i;</x></opencv_storage>\n",
        "xml external": '<?xml version="1.0"?>\n<!DOCTYPE l [<!ENTITY e SYSTEM '
        '"file:///etc/passwd">]>\n<opencv_storage><x>&e;</x></opencv_storage>\n',
        "xml not opencv": "<?xml version=\"1.0\"?>\n<root><a>1</a></root>\n",
        "xml empty": "",
    },
    ".json": {
        "json ok": ocj,
        "json truncated": ocj[: len(ocj) // 2],
        "json list": "[1, 2, 3]",
        "json null": "null",
        "json nan": ocj.replace("400.", "NaN", 1),
        "json deep": "{\"a\": " + "[" * 100000 + "]" * 100000 + "}",
        "json empty": "",
        "json 1e999": ocj.replace("400.", "1e999", 1),
    },
}

files: list[tuple[str, Path]] = []
for i, (label, text) in enumerate(texts.items()):
    path = cases_dir / f"r{i:03d}.toml"
    data = text if isinstance(text, bytes) else text.encode("utf-8")
    path.write_bytes(data)
    files.append((label, path))
j = 0
for suffix, group in ocv_cases.items():
    for label, text in group.items():
        path = cases_dir / f"o{j:03d}{suffix}"
        j += 1
        path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
        files.append((label, path))

# special files
special = cases_dir / "folder.toml"
special.mkdir(exist_ok=True)
files.append(("a folder", special))
fifo = cases_dir / "fifo.toml"
if not fifo.exists():
    os.mkfifo(fifo)
files.append(("a FIFO", fifo))
files.append(("/dev/zero", Path("/dev/zero")))
files.append(("/dev/null", Path("/dev/null")))
link = cases_dir / "loop.toml"
if not link.is_symlink():
    link.symlink_to(link)
files.append(("link loop", link))
files.append(("a session", work / "s.mcap"))
files.append(("missing", cases_dir / "nope.toml"))
files.append(("empty name", Path("")))

only = set(sys.argv[2:])
tally: Counter = Counter()
out = work / "rigout"
out.mkdir(exist_ok=True)


def digest(p: Path) -> str | None:
    try:
        return hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None
    except OSError:
        return None


for label, path in files:
    if only and label not in only:
        continue
    before = digest(path)
    results = []
    check = run("rig", "check", path, timeout=120)
    results.append(("check", check))
    results.append(("show", run("rig", "show", path, timeout=120)))
    results.append(("import", run("rig", "import", path, "-o", out / "i.toml", "--force",
                                  timeout=120)))
    results.append(("export", run("rig", "export", path, "--format", "opencv", "-o",
                                  out / "e.yml", "--force", timeout=120)))
    if check[0] == "ok" or check[0] == "ok-notes":
        results.append(("simulate", run("simulate", "--rig", path, "--duration", "0.5",
                                        "--seed", "71002", "-o", out / "sim.mcap", "--force",
                                        timeout=120)))
        results.append(("fuse", run("fuse", work / "s.mcap", "--rig", path, "--method",
                                    "typeA", "-o", out / "fu.mcap", "--force", timeout=120)))
    if digest(path) != before:
        results.append(("INPUT CHANGED", ("MODIFIED", None, "", "")))
    for what, (kind, _code, _so, se) in results:
        tally[kind] += 1
        first = (se.strip().splitlines() or [""])[-1][:150]
        flag = "" if kind in ("ok", "ok-notes", "error1", "error2") else "  <<<<<"
        print(f"{label:24} {what:8} {kind:9} {first}{flag}", flush=True)
print(dict(tally))
