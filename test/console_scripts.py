"""The console scripts setup.py installs, read from its source (no install needed)."""
import ast
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def console_scripts() -> dict:
    """{console script: its entry point, ``module:function``} of setup.py."""
    with open(os.path.join(ROOT, 'setup.py'), encoding='utf-8') as f:
        tree = ast.parse(f.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for k, v in zip(node.keys, node.values):
                if isinstance(k, ast.Constant) and k.value == 'console_scripts':
                    pairs = [s.split('=') for s in ast.literal_eval(v)]
                    return {a.strip(): b.strip() for a, b in pairs}
    raise AssertionError('no console_scripts in setup.py')
