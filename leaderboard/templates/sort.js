document.querySelectorAll('th button[data-band]').forEach(function (button) {
  button.addEventListener('click', function (event) {
    event.preventDefault();
    var band = button.dataset.band, body = document.querySelector('#ranking tbody');
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {
      var x = a.dataset['ap' + band], y = b.dataset['ap' + band];
      if (x === '' && y === '') return 0; if (x === '') return 1; if (y === '') return -1;
      return parseFloat(y) - parseFloat(x);
    });
    rows.forEach(function (row) { body.appendChild(row); });
    document.querySelectorAll('th button[data-band]').forEach(function (b) {
      b.setAttribute('aria-pressed', b === button ? 'true' : 'false');
    });
  });
});
