// Sorting by a band ranks by it, as the server does (ranking.ranked): higher AP first, a band without
// ground truth last, ties listing the earlier submission first; equal AP shares a rank.
function bandAp(row, band) {
  var value = row.dataset['ap' + band];
  return value === '' ? null : parseFloat(value);
}
document.querySelectorAll('th button[data-band]').forEach(function (button) {
  button.addEventListener('click', function (event) {
    event.preventDefault();
    var band = button.dataset.band, body = document.querySelector('#ranking tbody');
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {
      var x = bandAp(a, band), y = bandAp(b, band);
      if ((x === null) !== (y === null)) return x === null ? 1 : -1;
      if (x !== y) return y - x;
      if (a.dataset.submitted !== b.dataset.submitted) return a.dataset.submitted < b.dataset.submitted ? -1 : 1;
      return Number(a.dataset.id) - Number(b.dataset.id);
    });
    var rank = 0, previous = null;
    rows.forEach(function (row, position) {
      var value = bandAp(row, band);
      if (position === 0 || value !== previous) { rank = position + 1; previous = value; }
      row.querySelector('td.rank').textContent = rank;
      body.appendChild(row);
    });
    document.querySelectorAll('th button[data-band]').forEach(function (b) {
      b.setAttribute('aria-pressed', b === button ? 'true' : 'false');
    });
  });
});
