"""The page's module graph for `<link rel="modulepreload">` (asibot.web.preload)."""

from __future__ import annotations

import os

from asibot.web.preload import ModuleGraph, imports_of


def test_static_imports_only_in_order_and_none_from_comments() -> None:
    source = """// import { gone } from './commented.js';
import { a } from './a.js';
import {
  b,
  c,
} from "./b.js";
import './side-effect.js';
export { d } from './d.js';
/* import x from './block-comment.js'; */
const view = await import('./views/lazy.js');     // a tab's module: left to its tab
import * as THREE from '/static/vendor/three.js';
"""
    assert imports_of(source) == ["./a.js", "./b.js", "./side-effect.js", "./d.js", "/static/vendor/three.js"]


def test_the_graph_follows_imports_once_each_and_sees_edits(tmp_path) -> None:
    js = tmp_path / "js"
    (js / "views").mkdir(parents=True)
    (js / "main.js").write_text("import { a } from './a.js';\nimport './b.js';\nimport('./views/v.js');\n")
    (js / "a.js").write_text("import { b } from './b.js';\nimport { t } from '/static/vendor/t.js';\n")
    (js / "b.js").write_text("import { a } from './a.js';\nimport x from 'https://elsewhere.example/x.js';\n")
    (js / "views" / "v.js").write_text("import { a } from '../a.js';\n")
    (tmp_path / "vendor").mkdir()
    (tmp_path / "vendor" / "t.js").write_text("export const t = 1;\n")
    graph = ModuleGraph(tmp_path, "/static/", "js/main.js")
    assert graph.urls() == ["/static/js/a.js", "/static/js/b.js", "/static/vendor/t.js"]

    (js / "b.js").write_text("import { c } from './c.js';\n")
    stamp = os.stat(js / "b.js").st_mtime + 1
    os.utime(js / "b.js", (stamp, stamp))           # a clock too coarse to see the edit
    (js / "c.js").write_text("export const c = 1;\n")
    assert graph.urls() == ["/static/js/a.js", "/static/js/b.js", "/static/vendor/t.js", "/static/js/c.js"]


def test_an_import_out_of_the_folder_or_missing_is_left_to_the_browser(tmp_path) -> None:
    (tmp_path / "js").mkdir()
    (tmp_path / "js" / "main.js").write_text("import '../../../etc/passwd.js';\nimport './missing.js';\n")
    assert ModuleGraph(tmp_path, "/static", "js/main.js").urls() == ["/static/js/missing.js"]
