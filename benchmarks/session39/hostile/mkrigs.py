import pathlib
import re

base = pathlib.Path("rig.toml").read_text()
cases = {
 "nanf": base.replace("K = [[400.0", "K = [[nan", 1),
 "inff": base.replace("K = [[400.0", "K = [[inf", 1),
 "negf": base.replace("K = [[400.0", "K = [[-400.0", 1),
 "zerof": base.replace("K = [[400.0", "K = [[0.0", 1),
 "tinyf": base.replace("K = [[400.0", "K = [[1e-300", 1),
 "hugef": base.replace("K = [[400.0", "K = [[1e300", 1),
 "skew": base.replace("K = [[400.0, 0.0", "K = [[400.0, 5.0", 1),
 "krow": base.replace("[0.0, 0.0, 1.0]]", "[0.0, 0.0, 2.0]]", 1),
 "dup": base.replace('name = "cam2"', 'name = "cam1"'),
 "dupcase": base.replace('name = "cam2"', 'name = "CAM1"'),
 "dupspace": base.replace('name = "cam2"', 'name = "cam1 "'),
 "emptyname": base.replace('name = "cam2"', 'name = ""'),
 "nonorth": base.replace("R = [[0.0, -1.0, 0.0]", "R = [[0.0, -1.1, 0.0]", 1),
 "reflect": base.replace("R = [[0.0, -1.0, 0.0]", "R = [[0.0, 1.0, 0.0]", 1),
 "nanR": base.replace("R = [[0.0, -1.0, 0.0]", "R = [[nan, -1.0, 0.0]", 1),
 "nant": base.replace("t = [1.0,", "t = [nan,", 1),
 "hugt": base.replace("t = [1.0,", "t = [1e300,", 1),
 "t2": base.replace("t = [1.0, ", "t = [", 1),
 "dist4": base.replace("dist = [0.0, 0.0, 0.0, 0.0, 0.0]", "dist = [0.0, 0.0, 0.0, 0.0]", 1),
 "dist14": base.replace("dist = [0.0, 0.0, 0.0, 0.0, 0.0]", "dist = [" + ",".join(["0.0"]*14) + "]", 1),  # noqa: E501
 "dist3": base.replace("dist = [0.0, 0.0, 0.0, 0.0, 0.0]", "dist = [0.0, 0.0, 0.0]", 1),
 "distnan": base.replace("dist = [0.0, 0.0, 0.0, 0.0, 0.0]", "dist = [nan, 0.0, 0.0, 0.0, 0.0]", 1),
 "empty": 'name = "x"\n',
 "emptylist": 'name = "x"\ncamera = []\n',
 "fps0": base.replace("fps = 30.0", "fps = 0.0", 1),
 "fpsneg": base.replace("fps = 30.0", "fps = -30.0", 1),
 "fpsnan": base.replace("fps = 30.0", "fps = nan", 1),
 "fpsinf": base.replace("fps = 30.0", "fps = inf", 1),
 "fpshuge": base.replace("fps = 30.0", "fps = 1e12", 1),
 "fpstiny": base.replace("fps = 30.0", "fps = 1e-9", 1),
 "offneg": base.replace("offset = 0.0", "offset = -0.01", 1),
 "offnan": base.replace("offset = 0.0", "offset = nan", 1),
 "offbig": base.replace("offset = 0.0", "offset = 0.05", 1),
 "w0": base.replace("width = 640", "width = 0", 1),
 "wneg": base.replace("width = 640", "width = -640", 1),
 "wfloat": base.replace("width = 640", "width = 640.5", 1),
 "wstr": base.replace("width = 640", 'width = "640"', 1),
 "wbool": base.replace("width = 640", 'width = true', 1),
 "fpsbool": base.replace("fps = 30.0", 'fps = true', 1),
 "ppout": base.replace("319.5]", "1e6]", 1),
 "unknownkey": base.replace("fps = 30.0", "fps = 30.0\nfoo = 1", 1),
 "misskey": base.replace("fps = 30.0\n", "", 1),
 "missK": re.sub(r"K = \[\[400.0, 0.0, 319.5\].*\n", "", base, count=1),
 "nametype": base.replace('name = "cam2"', 'name = 2'),
 "camtable": 'name = "x"\n[camera]\nname = "a"\n',
 "namenl": base.replace('name = "cam2"', 'name = "ca\\nm2"'),
 "rigname_int": base.replace('name = "paper3"', 'name = 3'),
 "Krag": base.replace("[0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]", "[0.0, 400.0], [0.0, 0.0, 1.0]]", 1),
 "onecam": base.split("[[camera]]")[0] + "[[camera]]" + base.split("[[camera]]")[1],
 "bom_utf16": None,
 "latin1": base.replace('name = "cam2"', 'name = "cam\xe9"'),
}
for k, v in cases.items():
    if k == "bom_utf16":
        pathlib.Path("r_" + k + ".toml").write_bytes(base.encode("utf-16"))
    elif k == "latin1":
        pathlib.Path("r_" + k + ".toml").write_bytes(v.encode("latin-1"))
    else:
        pathlib.Path("r_" + k + ".toml").write_text(v)
