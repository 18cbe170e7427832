"""Times the Python libraries upstream's office metrics are built on, on the files
`officebench --keep DIR` wrote, so the Rust figures have a baseline.

What each case does mirrors the work of upstream's metric, not its code:
- compare_table sheet_data: open both workbooks with openpyxl (upstream loads them
  to read sheet names), read the first sheet of each with pandas, compare the frames;
- compare_docx_files: open both documents with python-docx, collect paragraph texts,
  compare them.

Usage: pip install openpyxl pandas python-docx; python3 office_upstream.py DIR [iterations]
"""
import statistics
import sys
import time

import openpyxl
import pandas as pd
from docx import Document


def timed(label, fn, iterations):
    fn()
    samples = []
    for _ in range(iterations):
        started = time.perf_counter()
        fn()
        samples.append((time.perf_counter() - started) * 1000)
    print(f"{label:<40} n={iterations:<3} mean={statistics.mean(samples):9.2f} ms  p50={statistics.median(samples):9.2f} ms")


def sheet_data(a, b):
    openpyxl.load_workbook(a)
    openpyxl.load_workbook(b)
    left = pd.read_excel(a, sheet_name=0)
    right = pd.read_excel(b, sheet_name=0)
    return left.equals(right)


def docx_texts(a, b):
    left = [p.text for p in Document(a).paragraphs]
    right = [p.text for p in Document(b).paragraphs]
    return left == right


def main():
    folder = sys.argv[1]
    iterations = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    xa, xb = f"{folder}/result.xlsx", f"{folder}/gold.xlsx"
    da, db = f"{folder}/result.docx", f"{folder}/gold.docx"
    timed("python compare_table sheet_data", lambda: sheet_data(xa, xb), iterations)
    timed("python compare_docx_files", lambda: docx_texts(da, db), iterations)


if __name__ == "__main__":
    main()
