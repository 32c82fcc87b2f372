// SlipEditor: a Python code editor (vendored CodeMirror 5) behind a small interface that
// pages share: create(textarea, {readOnly}) -> {getValue, setValue, markLine, clearMarks, focus}.
// Load vendor/codemirror/codemirror.js and mode/python.js before this file.
"use strict";

const SlipEditor = {
  create(textarea, options = {}) {
    const cm = window.CodeMirror.fromTextArea(textarea, {
      mode: "python",
      lineNumbers: true,
      indentUnit: 4,
      tabSize: 4,
      indentWithTabs: false,
      readOnly: Boolean(options.readOnly),
      viewportMargin: Infinity,
      extraKeys: {
        Tab: (editor) => editor.execCommand(editor.somethingSelected() ? "indentMore" : "insertSoftTab"),
        "Shift-Tab": "indentLess",
        // Keyboard users leave the editor with Escape, then Tab.
        Esc: (editor) => editor.getInputField().blur(),
      },
    });
    let marked = [];
    // Keep the textarea in step, so a form reading it sees the editor's text.
    cm.on("change", () => cm.save());
    return {
      getValue: () => cm.getValue(),
      setValue(text) {
        cm.setValue(text);
        cm.save();
      },
      // Mark 1-based line `lineNumber` with `message` (the editor's tooltip).
      markLine(lineNumber, message) {
        const line = Math.min(Math.max(lineNumber - 1, 0), cm.lineCount() - 1);
        const handle = cm.addLineClass(line, "background", "slip-error-line");
        cm.addLineClass(line, "gutter", "slip-error-gutter");
        cm.getWrapperElement().title = message || "";
        marked.push(handle);
        cm.scrollIntoView({ line, ch: 0 }, 40);
        cm.getWrapperElement().dataset.markedLines = marked.map((h) => cm.getLineNumber(h) + 1).join(",");
      },
      clearMarks() {
        for (const handle of marked) {
          cm.removeLineClass(handle, "background", "slip-error-line");
          cm.removeLineClass(handle, "gutter", "slip-error-gutter");
        }
        marked = [];
        delete cm.getWrapperElement().dataset.markedLines;
        cm.getWrapperElement().removeAttribute("title");
      },
      focus: () => cm.focus(),
      codemirror: cm,
    };
  },
};
