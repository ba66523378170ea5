// The equations MathJax cannot typeset (tests/test_docs.py): reads [[tex, display], ...] as
// JSON on stdin, prints [[tex, MathJax's error], ...]. Run by node with MathJax's folder
// (the [docs] extra's es5/) as its argument; its TeX input has every package the site's
// tex-svg-full.js has, but an undefined macro is an error here (the browser shows it in red).
const es5 = process.argv[2];
const equations = JSON.parse(require("fs").readFileSync(0, "utf8"));
require(es5 + "/node-main.js")
  .init({loader: {load: ["adaptors/liteDOM", "input/tex-full"]},
         tex: {packages: {"[-]": ["noundefined", "bussproofs"]}}})      // bussproofs needs an output jax
  .then((MathJax) => {
    const failed = [];
    for (const [tex, display] of equations) {
      const mml = MathJax.tex2mml(tex, {display});
      if (mml.includes("<merror")) failed.push([tex, (mml.match(/data-mjx-error="([^"]*)"/) || [mml])[1] || mml]);
    }
    process.stdout.write(JSON.stringify(failed));
  })
  .catch((err) => { console.error(err.message); process.exit(1); });
