import pathlib

rows = []
for i in range(60):
    t = i / 90
    for c, cam in enumerate(["cam1", "cam2", "cam3"]):
        if i % 3 == c:
            rows.append((cam, t, 320 + i, 240 + 0.5 * i))
hdr = "camera,time,u,v\n"
good = hdr + "".join(f"{c},{t:.9f},{u},{v}\n" for c, t, u, v in rows)
P = pathlib.Path
P("c_good.csv").write_text(good)
P("c_bom.csv").write_bytes(b"\xef\xbb\xbf" + good.encode())
P("c_crlf.csv").write_bytes(good.replace("\n", "\r\n").encode())
P("c_cr.csv").write_bytes(good.replace("\n", "\r").encode())
P("c_misscol.csv").write_text("camera,time,u\n" + "".join(f"{c},{t},{u}\n" for c, t, u, v in rows))
P("c_extracol.csv").write_text("camera,time,u,v,foo\n" + "".join(f"{c},{t},{u},{v},x\n" for c, t, u, v in rows))  # noqa: E501
P("c_extracell.csv").write_text(hdr + "".join(f"{c},{t},{u},{v},7\n" for c, t, u, v in rows))
P("c_nonnum.csv").write_text(good.replace("320", "abc", 1))
P("c_huge.csv").write_text(good.replace(",320,", ",1e300,", 1))
P("c_hugetime.csv").write_text(good.replace("0.000000000", "1e300", 1))
P("c_nantime.csv").write_text(good.replace("0.000000000", "nan", 1))
P("c_inftime.csv").write_text(good.replace("0.000000000", "inf", 1))
P("c_nanpx.csv").write_text(good.replace(",320,", ",nan,", 1))
P("c_unsorted.csv").write_text(hdr + "".join(f"{c},{t:.9f},{u},{v}\n" for c, t, u, v in reversed(rows)))  # noqa: E501
P("c_dup.csv").write_text(good + good.split("\n", 1)[1])
P("c_headeronly.csv").write_text(hdr)
P("c_empty.csv").write_text("")
P("c_reorder.csv").write_text("time,camera,v,u\n" + "".join(f"{t},{c},{v},{u}\n" for c, t, u, v in rows))  # noqa: E501
P("c_upper.csv").write_text("CAMERA,TIME,U,V\n" + good.split("\n", 1)[1])
P("c_spaces.csv").write_text("camera, time, u, v\n" + "".join(f"{c}, {t}, {u}, {v}\n" for c, t, u, v in rows))  # noqa: E501
P("c_semicolon.csv").write_text(good.replace(",", ";"))
P("c_unknowncam.csv").write_text(good + "cam9,0.5,100,100\n")
P("c_quoted.csv").write_text(hdr + "".join(f'"{c}","{t}","{u}","{v}"\n' for c, t, u, v in rows))
P("c_utf16.csv").write_bytes(good.encode("utf-16"))
P("c_nul.csv").write_bytes(good.encode().replace(b"cam2", b"ca\x00m2", 1))
P("c_negpx.csv").write_text(good.replace(",320,", ",-5,", 1))
P("c_bigpx.csv").write_text(good.replace(",320,", ",1e7,", 1))
P("c_frame_neg.csv").write_text("camera,time,u,v,frame\n" + "".join(f"{c},{t},{u},{v},{-i}\n" for i,(c, t, u, v) in enumerate(rows)))  # noqa: E501
P("c_frame_float.csv").write_text("camera,time,u,v,frame\n" + "".join(f"{c},{t},{u},{v},{i}.5\n" for i,(c, t, u, v) in enumerate(rows)))  # noqa: E501
P("c_frame_huge.csv").write_text("camera,time,u,v,frame\n" + "".join(f"{c},{t},{u},{v},{2**70}\n" for i,(c, t, u, v) in enumerate(rows)))  # noqa: E501
P("c_score_nan.csv").write_text("camera,time,u,v,frame,score\n" + "".join(f"{c},{t},{u},{v},{i},nan\n" for i,(c, t, u, v) in enumerate(rows)))  # noqa: E501
P("c_score_neg.csv").write_text("camera,time,u,v,frame,score\n" + "".join(f"{c},{t},{u},{v},{i},-1\n" for i,(c, t, u, v) in enumerate(rows)))  # noqa: E501
P("c_dup_hdr.csv").write_text("camera,time,u,v,u\n" + "".join(f"{c},{t},{u},{v},{u}\n" for c, t, u, v in rows))  # noqa: E501
P("c_same_time_same_cam.csv").write_text(hdr + "".join(f"cam1,0.0,{u},{v}\n" for c, t, u, v in rows))  # noqa: E501
P("c_time_backwards_frames.csv").write_text("camera,time,u,v,frame\n" + "".join(f"{c},{t},{u},{v},{60-i}\n" for i,(c, t, u, v) in enumerate(rows)))  # noqa: E501
P("c_onlyu.csv").write_text(good.replace(",320,240.0", ",320,", 1))
P("c_longline.csv").write_text(hdr + "cam1," + "1"*10_000_000 + ",3,4\n")
P("c_tabs.csv").write_text(good.replace(",", "\t"))
P("c_exp.csv").write_text(good.replace("0.011111111", "1.1111111e-2", 1))
P("c_hex.csv").write_text(good.replace(",320,", ",0x140,", 1))
P("c_underscore.csv").write_text(good.replace(",320,", ",3_20,", 1))
P("c_infinity.csv").write_text(good.replace(",320,", ",Infinity,", 1))
