"""Code stays small enough to read in one sitting: no module of the project's packages over 500 lines, no
function over 80 (argparse builders aside: a flag and its help are one statement each, read one at a time)."""
import ast

from tests.paths import ROOT

PACKAGES = ("tamp", "evaluation", "learned", "symbolic")
MAX_LINES, MAX_FUNCTION_LINES = 500, 80
PARSER_CALLS = {"add_argument", "add_parser", "add_argument_group", "add_mutually_exclusive_group", "set_defaults"}


def sources() -> dict[str, str]:
    return {str(p.relative_to(ROOT)): p.read_text() for package in PACKAGES for p in (ROOT / package).rglob("*.py")}


def builds_a_parser(function: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Whether most of the function's statements add flags or subcommands to an argparse parser."""
    calls = [node for node in ast.walk(function) if isinstance(node, ast.Call)
             and isinstance(node.func, ast.Attribute) and node.func.attr in PARSER_CALLS]
    return len(calls) >= len(function.body) / 2


def long_functions(source: str) -> dict[str, int]:
    """The functions (methods too) of a module over MAX_FUNCTION_LINES lines, but argparse builders."""
    return {node.name: node.end_lineno - node.lineno + 1 for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES and not builds_a_parser(node)}


def test_no_module_of_the_packages_is_over_500_lines():
    sizes = {path: len(text.splitlines()) for path, text in sources().items()}
    assert len(sizes) > 50 and not {p: n for p, n in sizes.items() if n > MAX_LINES}


def test_no_function_is_over_80_lines_but_argparse_builders():
    assert not {path: found for path, text in sources().items() if (found := long_functions(text))}


def test_the_function_check_sees_a_long_function_and_spares_a_parser_builder():
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    flags = "\n".join(f"    p.add_argument('--f{i}')" for i in range(MAX_FUNCTION_LINES))
    assert long_functions(f"def long():\n{body}\n") == {"long": MAX_FUNCTION_LINES + 1}
    assert long_functions(f"def add_flags(p):\n{flags}\n") == {}
