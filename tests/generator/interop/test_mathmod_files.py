"""MathMod's files as MathMod writes them: DOTSYMBOL decimal points, keys with stray blanks,
strings broken over lines, and the models surfgen refuses (Vect, Import) with one clear line."""

from __future__ import annotations

import numpy as np
import pytest

from surfgen.generator.errors import SpecError
from surfgen.generator.eval.evaluate import evaluate
from surfgen.generator.formula import limits
from surfgen.generator.formula.parser import tokenize
from surfgen.generator.interop.mathmod import build_model, load_model, model_names, parse_script

# Written the way MathMod's own collection files are: tabs, DOTSYMBOL in every decimal number
# (formulas, bounds, constants, Funct bodies, slider positions), a key with a trailing blank.
COLLECTION = """{
\t"MathModels": [{
\t\t"Iso3D": {
\t\t\t"Name": ["Blob"],
\t\t\t"Component": ["Blob"],
\t\t\t"Const": ["c=0DOTSYMBOL5", "r=c+1DOTSYMBOL25"],
\t\t\t"Funct": ["Sph=x^2+y^2+z^2-r^2", "Bump=Sph(x,y,z,t)+0DOTSYMBOL2*cos(4*x)*cos(4*y)"],
\t\t\t"Fxyz": ["Bump(x,y,z,t)*A"],
\t\t\t"Xmin": ["-2DOTSYMBOL5"], "Xmax": ["2DOTSYMBOL5"],
\t\t\t"Ymin": ["-2DOTSYMBOL5"], "Ymax": ["2DOTSYMBOL5"],
\t\t\t"Zmin": ["-2DOTSYMBOL5"], "Zmax": ["2DOTSYMBOL5"],
\t\t\t"Grid": ["24"],
\t\t\t"Description ": ["A blob by somebody, DOTSYMBOL-free text"]
\t\t},
\t\t"Sliders": {"Name": ["A"], "Position": ["1DOTSYMBOL5", "2"], "Min": ["0"], "Max": ["3"]},
\t\t"Texture": {"Colors": ["R=0DOTSYMBOL8", "G=0DOTSYMBOL6", "B=0DOTSYMBOL4", "T=1"]}
\t}]
}"""


def test_dotsymbol_is_the_decimal_point_everywhere() -> None:
    model = load_model(parse_script(COLLECTION))
    spec = model.components[0].spec
    assert spec.box == (-2.5, 2.5, -2.5, 2.5, -2.5, 2.5)
    assert spec.params == {"A": 1.5, "r": 1.75}
    assert "0.2" in spec.formula and "DOTSYMBOL" not in spec.formula
    # the first slider set, then the second
    assert load_model(parse_script(COLLECTION), slider_set=1).components[0].spec.params["A"] == 2.0


def test_the_older_dot_token_too() -> None:
    text = COLLECTION.replace("DOTSYMBOL", "$DOT$")
    assert load_model(parse_script(text)).components[0].spec.box[0] == -2.5


def test_a_key_with_a_trailing_blank_is_read_as_the_key() -> None:
    model = load_model(parse_script(COLLECTION))
    assert model.description.startswith("A blob by somebody")
    assert model.notices == ("ignored: Texture (colour formulas)",)


def test_keys_mathmod_does_not_use_are_ignored_with_a_notice() -> None:
    doc = parse_script(
        '{"Iso3D": {"Name": ["S"], "Fxyz": ["x^2+y^2+z^2-1"], "Xmin": ["-2"], "Xmax": ["2"],'
        ' "Ymin": ["-2"], "Ymax": ["2"], "Zmin": ["-2"], "Zmax": ["2"], "Colour": ["red"]},'
        ' "Shader": 1}'
    )
    model = build_model(doc[0])
    assert model.notices == (
        "ignored: unknown key 'Shader' in a model",
        "ignored: unknown key 'Colour' in Iso3D",
    )
    # the exact key wins over a blank-padded copy, which is then ignored
    both = {"Iso3D": {**doc[0]["Iso3D"], "Name": ["Exact"], "Name ": ["Padded"]}}
    model = build_model(both)
    assert model.name == "Exact" and "ignored: unknown key 'Name ' in Iso3D" in model.notices


def test_a_formula_broken_over_lines_reads_as_mathmod_reads_it() -> None:
    # raw line breaks inside a JSON string: invalid JSON, but MathMod drops them before parsing
    text = COLLECTION.replace('"Bump(x,y,z,t)*A"', '"Bump(x,y,z,t)\n*A"')
    assert load_model(parse_script(text)).components[0].spec.formula == (
        load_model(parse_script(COLLECTION)).components[0].spec.formula
    )


def test_invalid_json_still_names_its_line_in_the_file() -> None:
    text = COLLECTION.replace('"Grid": ["24"],', '"Grid": ["24"],,')
    with pytest.raises(SpecError, match=r"not valid JSON \(.* at line 12\)"):
        parse_script(text)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("Vect", ["v=1,2,3"], "not supported: Vect (vector constants) in model S"),
        ("Import", ["libfoo.so"], "not supported: Import (imported C++ functions) in model S"),
    ],
)
def test_vect_and_import_are_refused_in_one_line(key: str, value: list, message: str) -> None:
    doc = parse_script(
        '{"Iso3D": {"Name": ["S"], "Fxyz": ["x^2+y^2+z^2-1"], "Xmin": ["-2"], "Xmax": ["2"],'
        ' "Ymin": ["-2"], "Ymax": ["2"], "Zmin": ["-2"], "Zmax": ["2"]}}'
    )
    doc[0]["Iso3D"][key] = value
    with pytest.raises(SpecError) as err:
        build_model(doc[0])
    assert str(err.value) == message


def chain(levels: int, width: int) -> str:
    """A generated model, as MathMod's generators write them: each Funct calls the previous one
    ``width`` times, shifted, so the formula written out grows as width^levels."""
    functs = ['"f0=x^2+y^2+z^2-1DOTSYMBOL0+0DOTSYMBOL01*x*y*z-0DOTSYMBOL02*x*y"']
    for i in range(1, levels):
        terms = "+".join(
            f"0DOTSYMBOL{j + 1}*f{i - 1}(x+0DOTSYMBOL0{j},y,z,t)" for j in range(width)
        )
        functs.append(f'"f{i}=({terms})/{width}"')
    return (
        '{"Iso3D": {"Name": ["Chain"], "Funct": [' + ", ".join(functs) + "],"
        f' "Fxyz": ["f{levels - 1}(x,y,z,t)"], "Xmin": ["-2"], "Xmax": ["2"], "Ymin": ["-2"],'
        ' "Ymax": ["2"], "Zmin": ["-2"], "Zmax": ["2"], "Grid": ["10"]}}'
    )


def test_a_long_generated_model_renders() -> None:
    # over 100,000 tokens once its Functs are inlined (the old token limit), a fraction of the
    # node limit: an ordinary MathMod model, read, printed, parsed back and evaluated
    spec = load_model(parse_script(chain(8, 3))).components[0].spec
    assert len(tokenize(spec.formula)) > 100_000
    field = evaluate(spec.tree(), spec.to_grid(), spec.params)
    assert np.isfinite(field.values).all() and (field.values < 0).any() and (field.values > 0).any()


def test_a_model_too_large_once_inlined_is_one_line_naming_the_funct(monkeypatch) -> None:
    monkeypatch.setattr(limits, "MAX_FORMULA_NODES", 20_000)  # reached in a few levels
    with pytest.raises(SpecError) as err:
        load_model(parse_script(chain(40, 2)))
    message = str(err.value)
    assert message.startswith("model Chain, Funct f") and "formula too large" in message
    assert "\n" not in message


def test_model_level_keys_with_blanks_are_found_by_name() -> None:
    # "Iso3D " and "Name " as a hand-edited file may have them: the model is found and named
    text = (
        '{"MathModels": [{"Iso3D ": {"Name ": ["Ball"], "Fxyz": ["x^2+y^2+z^2-1"],'
        ' "Xmin": ["-2"], "Xmax": ["2"], "Ymin": ["-2"], "Ymax": ["2"], "Zmin": ["-2"],'
        ' "Zmax": ["2"]}}]}'
    )
    models = parse_script(text)
    assert model_names(models) == ["Ball"]
    assert load_model(models, "Ball").name == "Ball"
